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

# includes_only WHO ALLOWED FILES...: every '#include "mcstat/X"' in FILES must match ALLOWED.
includes_only() {
  local who=$1 allowed=$2
  shift 2
  while IFS=: read -r file line text; do
    local header=${text#*\"mcstat/}
    header=${header%%\"*}
    if ! [[ $header =~ ^($allowed)$ ]]; then
      echo "$file:$line: includes mcstat/$header; $who may include only mcstat/($allowed)"
      bad=1
    fi
  done < <(grep -Hn '^#include "mcstat/' "$@")
}

# rule FOLDER ALLOWED: one rule per folder (issue 51). A folder is a room: its sources FOLDER/*,
# its public headers include/mcstat/FOLDER/* and its private shared ones include/mcstat/FOLDER/
# detail/* (not installed); a sub-folder with a rule of its own is a room of its own (maxdepth 1).
# Every '#include "mcstat/X"' of the room's files must match the extended regex ALLOWED (against X).
# The renderer keeps its headers beside it (render-fixture/include/mcstat/render-fixture/, not
# installed): its sources are render-fixture/src/.
rule() {
  local folder=$1 allowed=$2
  local dirs=("$folder" "include/mcstat/$folder" "include/mcstat/$folder/detail")
  [ "$folder" != render-fixture ] ||
    dirs=(render-fixture/src render-fixture/include/mcstat/render-fixture)
  local files
  files=$(find "${dirs[@]}" -maxdepth 1 -type f \( -name '*.h' -o -name '*.cpp' \) 2>/dev/null | sort)
  [ -n "$files" ] || { echo "check_arrows: folder $folder: no files"; bad=1; return; }
  includes_only "$folder" "$allowed" $files
}

# The headers of a room: public, and its detail/ (mcstat::detail, shared with the rooms above).
room() { echo "$1/(detail/)?[a-z_0-9]+\\.h"; }
core=$(room core)
codec="$core|$(room exr-deep/codec)"
format="$codec|$(room exr-deep)"
kernel='filters/(operation|estimate)\.h'
measures="$core|$(room analysis)"
spec="$format|$(room image/spec)"
onimage="$spec|filters/(operation|estimate|registry)\.h|$(room image)|$measures"
anything='[a-z_0-9/-]+\.h'

# Layer 0: core depends on nothing; the colour config stands beside the stack.
rule core "$core"
rule color "$core|$(room color)"
# Layer 1: OpenEXR through its Core API (no statistics file), then the file format (no operation).
rule exr-deep/codec "$codec"
rule exr-deep "$format"
# Layer 2: the operations. Each family reaches only the interface (operation.h, estimate.h); the
# per-pixel intervals implement filters/interval.h; the 3D filters read the buffer limit.
rule filters "$format|filters/.+\.h"
rule filters/pixel "$core|$kernel|filters/interval\.h|$(room filters/pixel)"
rule filters/window "$core|$kernel|$(room filters/window)|exr-deep/stats_file\.h"
rule filters/samples "$format|$kernel|filters/aov_weights\.h|$(room filters/samples)"
rule compact "$format|filters/.+\.h|$(room compact)"
# Layer 2, the measures: no image, no file.
rule analysis "$measures"
# Layer 3: the specs of images (below the operations), then the image layer, which runs every
# operation through its kernel and names no family; no tool, no ingest, no review.
rule image/spec "$spec"
rule image "$spec|filters/(operation|estimate|registry|aov_weights|removed_light|keep_light|keep_light_stream|interval)\.h|$(room image)|analysis/metrics\.h"
# Layer 4: ingest reads renderers' EXRs through the codec and sets up images through the spec
# library, not the operations. The review pictures and the comparison stand on the image layer and
# the measures, through the registry (no family), on no tool, no ingest and not on each other; only
# the comparison's reports draw with the review pictures.
rule ingest "$spec|color/color\.h|$(room ingest)"
rule review "$onimage|$(room review)|color/color\.h"
rule compare "$onimage|$(room compare)"
rule compare/report "$onimage|compare/compare\.h|$(room compare/report)|review/review_pictures\.h"
# Layer 5: the tools and the bindings stand on everything below them.
rule render-fixture "$anything"
rule oiiotool-ext "$anything"
rule oiio-plugin "$anything"
rule python/src "$anything"

# Within filters/: the operation interface and the registry name no family (one check, not a room:
# the files of filters/ above may name each family's header).
includes_only "the operation interface" "$core|$kernel" include/mcstat/filters/operation.h \
  include/mcstat/filters/estimate.h include/mcstat/filters/registry.h

# Public headers never include a detail/ header: the install leaves every detail/ folder out.
while IFS=: read -r file line text; do
  echo "$file:$line: a public header includes a private one (detail/, not installed)"
  bad=1
done < <(find include -name '*.h' -not -path '*/detail/*' -print0 | xargs -0 grep -Hn '^#include "mcstat/.*/detail/')

# Private headers: a quoted include that is not mcstat/... is a header of the includer's folder.
while IFS=: read -r file line text; do
  header=${text#*\"}
  header=${header%%\"*}
  if [ ! -f "$(dirname "$file")/$header" ]; then
    echo "$file:$line: includes \"$header\", which is not in its own folder (another room's private header)"
    bad=1
  fi
done < <(grep -rHn --include='*.h' --include='*.cpp' '^#include "' core color exr-deep filters \
  compact analysis image ingest review compare oiiotool-ext oiio-plugin render-fixture python/src 2>/dev/null |
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
