#!/usr/bin/env bash
# wrong_include.sh ROOT: check_arrows.sh must fail on a copy of the source with arrows pointing the
# wrong way, naming each: a per-pixel estimator that includes the image layer, the operation
# interface that includes a family, ingest that includes a private header of exr-deep, the review
# pictures that include the comparison (two rooms of layer 4), a public header that includes a
# private (detail/) one, which the install leaves out, and a tool that names Pajot (state parts
# are generic: only the method's own files name it).
set -euo pipefail
root=$(cd "${1:?usage: wrong_include.sh ROOT}" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for d in core color exr-deep filters compact analysis image ingest review compare oiiotool-ext \
  oiio-plugin render-fixture python include; do
  cp -r "$root/$d" "$tmp/$d"
done
"$root/tests/architecture/check_arrows.sh" "$tmp" >/dev/null ||
  { echo "the unchanged copy should pass"; exit 1; }
sed -i '0,/^#include "mcstat\//s//#include "mcstat\/image\/imageops.h"\n&/' "$tmp/filters/pixel/gmon.cpp"
sed -i '0,/^#include "mcstat\//s//#include "mcstat\/filters\/pixel\/pixel_estimate.h"\n&/' \
  "$tmp/include/mcstat/filters/operation.h"
sed -i '0,/^#include "mcstat\//s//#include "stats_layout.h"\n&/' "$tmp/ingest/ingest.cpp"
sed -i '0,/^#include "mcstat\//s//#include "mcstat\/compare\/compare.h"\n&/' "$tmp/review/review_pictures.cpp"
sed -i '0,/^#include "mcstat\//s//#include "mcstat\/filters\/pixel\/detail\/rank_keys.h"\n&/' \
  "$tmp/include/mcstat/filters/pixel/gmon.h"
# A tool that names Pajot: state parts are described through the registry entry's hooks.
echo '// printPajotSummary' >>"$tmp/oiiotool-ext/io.cpp"
set +e
out=$("$root/tests/architecture/check_arrows.sh" "$tmp")
rc=$?
set -e
echo "$out"
[ "$rc" -eq 1 ] || { echo "expected exit 1, got $rc"; exit 1; }
for want in "filters/pixel/gmon.cpp:[0-9]*: includes mcstat/image/imageops.h; filters/pixel may include only" \
  "include/mcstat/filters/operation.h:[0-9]*: includes mcstat/filters/pixel/pixel_estimate.h; the operation interface may include only" \
  "include/mcstat/filters/pixel/gmon.h:[0-9]*: a public header includes a private one" \
  "ingest/ingest.cpp:[0-9]*: includes \"stats_layout.h\", which is not in its own folder" \
  "review/review_pictures.cpp:[0-9]*: includes mcstat/compare/compare.h; review may include only" \
  "oiiotool-ext/io.cpp: names Pajot; only its own files"; do
  grep -q "$want" <<<"$out" || { echo "missing: $want"; exit 1; }
done
[ "$(wc -l <<<"$out")" -eq 6 ] || { echo "expected exactly 6 lines"; exit 1; }
echo "ok: the five wrong arrows and the tool naming Pajot are named"
