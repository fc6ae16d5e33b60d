#!/usr/bin/env bash
# check_arrows.sh ROOT: the include arrows of docs/architecture.md, checked. Every rule names the
# files of one room and the mcstat headers they may include; an include outside that list is an
# arrow pointing the wrong way. A quoted include that is not "mcstat/..." must name a header of the
# includer's own folder (a room's private header), never another room's. Prints one line per
# wrong arrow ("FILE:LINE: includes HEADER; ROOM may include only ...") and exits 1 when there
# is any, 0 otherwise. Run by CTest (tests/architecture/CMakeLists.txt).
set -uo pipefail
root=${1:?usage: check_arrows.sh ROOT}
cd "$root" || exit 2
bad=0

# rule ROOM ALLOWED FILES...: every '#include "mcstat/X"' in FILES must match the extended regex
# ALLOWED (matched against X).
rule() {
  local room=$1 allowed=$2
  shift 2
  local files
  files=$(find "$@" -maxdepth 1 -type f \( -name '*.h' -o -name '*.cpp' \) 2>/dev/null | sort)
  [ -n "$files" ] || { echo "check_arrows: room $room: no files in $*"; bad=1; return; }
  while IFS=: read -r file line text; do
    local header=${text#*\"mcstat/}
    header=${header%%\"*}
    if ! [[ $header =~ ^($allowed)$ ]]; then
      echo "$file:$line: includes mcstat/$header; $room may include only mcstat/($allowed)"
      bad=1
    fi
  done < <(grep -Hn '^#include "mcstat/' $files)
}

core='core/[a-z_]+\.h'
codec="$core|exr-codec/[a-z_]+\.h|temp_file\.h"
format="$codec|stats_file\.h|sample_records\.h|temp_file\.h"
kernel='filters/(operation|estimate)\.h'

# Layer 0: core depends on nothing.
rule core "$core" core include/mcstat/core
# The colour config stands beside the stack.
rule color "$core|color\.h" color
rule color "$core" include/mcstat/color.h
# Layer 1: OpenEXR through its Core API (no statistics file), then the file format (no operation).
rule exr-codec "$codec" exr-deep/codec include/mcstat/exr-codec
rule exr-deep "$format" exr-deep include/mcstat/stats_file.h include/mcstat/sample_records.h \
  include/mcstat/temp_file.h
# Layer 2: what an operation is names no family; each family reaches only the interface.
rule operation "$core|$kernel" include/mcstat/filters/operation.h include/mcstat/filters/estimate.h
rule registry "$core|$kernel" include/mcstat/filters/registry.h
# The per-pixel intervals implement filters/interval.h (the intervals from a stored spread).
rule pixel "$core|$kernel|filters/interval\.h|filters/pixel/[a-z_0-9]+\.h" filters/pixel include/mcstat/filters/pixel
rule window "$core|$kernel|filters/window/[a-z_0-9]+\.h|stats_file\.h" filters/window \
  include/mcstat/filters/window
rule samples "$format|$kernel|filters/aov_weights\.h|filters/samples/[a-z_0-9]+\.h" filters/samples \
  include/mcstat/filters/samples
rule filters "$format|filters/.+\.h" filters include/mcstat/filters
rule compact "$format|filters/.+\.h|compact/compact\.h" compact include/mcstat/compact
# Layer 2, the measures (analysis/): no image, no file.
rule measures "$core|analysis/(metrics|planner|two_sample)\.h" analysis include/mcstat/analysis
# Layer 3: the specs of images (below the operations), then the image layer, which runs every
# operation through its kernel and names no family; no tool, no ingest, no review.
rule imagespec "$format|image/(image_spec|render_layout)\.h" image/image_spec.cpp \
  image/render_layout.cpp include/mcstat/image/image_spec.h include/mcstat/image/render_layout.h
rule image "$format|filters/(operation|estimate|registry|aov_weights|removed_light|keep_light|interval)\.h|image/[a-z_]+\.h|analysis/metrics\.h" \
  image include/mcstat/image
# Layer 4: ingest reads renderers' EXRs through the codec, never the format's private headers,
# and sets up images through the spec library, not the operations.
rule ingest "$format|image/(image_spec|render_layout)\.h|color\.h|ingest\.h|channel_naming\.h" ingest \
  include/mcstat/ingest.h include/mcstat/channel_naming.h
# Layer 4 on the image layer: the review pictures and the comparison stand on the image layer and
# the measures, through the registry (no family of operations), and on no tool, no ingest and not
# on each other; only the comparison's reports draw with the review pictures.
onimage="$format|filters/(operation|estimate|registry)\.h|image/[a-z_]+\.h|analysis/(metrics|planner|two_sample)\.h"
rule review "$onimage|review/(review_pictures|display)\.h|color\.h" review include/mcstat/review
rule compare "$onimage|compare/compare\.h" compare/compare.cpp compare/compare_checks.cpp \
  compare/compare_checks.h compare/comparison.h compare/comparison.cpp compare/comparison_tile.cpp \
  compare/comparison_decision.cpp compare/comparison_maps.cpp compare/side_values.cpp \
  compare/compare_verdict.cpp compare/compare_params.cpp include/mcstat/compare/compare.h
rule compare-report "$onimage|compare/(compare|compare_report|report_folder)\.h|review/review_pictures\.h" \
  compare/compare_report.cpp include/mcstat/compare/compare_report.h
# A report folder (never a user's file lost) stands on the format layer's atomic writes alone.
rule report-folder "$format|compare/report_folder\.h" compare/report_folder.cpp \
  include/mcstat/compare/report_folder.h

# Private headers: a quoted include that is not mcstat/... is a header of the includer's folder.
while IFS=: read -r file line text; do
  header=${text#*\"}
  header=${header%%\"*}
  if [ ! -f "$(dirname "$file")/$header" ]; then
    echo "$file:$line: includes \"$header\", which is not in its own folder (another room's private header)"
    bad=1
  fi
done < <(grep -rHn --include='*.h' --include='*.cpp' '^#include "' core color exr-deep filters \
  compact analysis image ingest review compare oiiotool-ext oiio-plugin render-fixture 2>/dev/null |
  grep -v '^[^:]*:[0-9]*:#include "mcstat/')

# Operation state parts are generic (issue 35): the format and the tools know state parts by their
# owner, so Pajot is named only by its own files (named after the method, density-based sample
# delaying), its registry line and the renderer's flag (render-fixture/src/main.cpp); of the
# scripts, those that run the method by its flags and label its rows (its own benchmark, the trade
# of every method).
while IFS= read -r file; do
  case $file in
    filters/samples/sample_delaying* | include/mcstat/filters/samples/sample_delaying* | \
      scripts/bench_sample_delaying.sh | scripts/trade.sh | filters/registry.cpp | render-fixture/src/main.cpp) ;;
    *)
      echo "$file: names Pajot; only its own files (sample_delaying*), filters/registry.cpp and render-fixture/src/main.cpp may"
      bad=1
      ;;
  esac
done < <(grep -rIli --exclude='*.md' pajot core color exr-deep filters compact analysis image ingest \
  review compare oiiotool-ext oiio-plugin render-fixture include python scripts CMakeLists.txt 2>/dev/null | sort)

exit $bad
