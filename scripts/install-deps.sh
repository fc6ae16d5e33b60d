#!/usr/bin/env bash
# Installs the Debian 12 packages mcstat builds against, only those missing. Idempotent and quiet
# when everything is present. Needs root (or sudo) only when something must be installed.
set -euo pipefail

packages=(
  cmake g++ make pkg-config time
  ninja-build                            # scripts/build.sh: the generator of a new build folder
  libopenimageio-dev openimageio-tools   # images, threading, argument parsing; oiiotool for checks
  libopenexr-dev openexr                 # the statistics file; exrheader for checks
  libdeflate-dev                         # ZIP chunks of statistics files inflated and deflated
  libopencolorio-dev                     # display transforms and luma coefficients
  libembree-dev libtbb-dev               # the fixture renderer's ray tracing
  libfmt-dev nlohmann-json3-dev          # formatting, scene files
  libboost-math1.74-dev                  # --compare: Student t and normal distributions (header-only Boost.Math)
  libgtest-dev libbenchmark-dev          # tests and benchmarks
  gnuplot-nox                            # mcstat --qualityplot draws its plot with gnuplot (pngcairo)
  fonts-dejavu-core                      # OIIO's render_text needs a font: DejaVuSans labels the review pictures
  clang libclang-rt-14-dev               # the sanitizer suite and the fuzzers: clang, libFuzzer, ASan/UBSan runtimes
  lld                                    # cmake/Linker.cmake: links in a fraction of GNU ld's time
  clang-format                           # tests/architecture/check_format.sh: every C++ file as .clang-format writes it
  blender python3-numpy python3-openimageio  # tests/aovs: real Cycles renders through ingest, checked in Python
  graphviz                               # dot: docs/images/architecture.png is drawn from architecture.dot
  slurm-wlm munge                        # farm/: a shot's seeds as Slurm tasks (tests/farm runs a one-node cluster)
  pybind11-dev python3-dev python3-pytest  # python/: the mcstat Python module and its pytest suite (Debian's python3)
  python3-matplotlib                     # python/examples/plot_pixel.py plots a pixel's sub-buffers
  python3-scipy                          # scripts/keep_light_model.py (convolutions), keep_light_table.sh (t intervals)
  chromium                               # tests/compare: --compare:html's report opened in a real headless browser
  python3-junitparser                    # tests/compare: --compare:junit's XML read back by a JUnit consumer's parser
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "install-deps: installing ${missing[*]}"
sudo=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root to install: ${missing[*]}" >&2; exit 1; }
  sudo="sudo"
fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -q
$sudo apt-get install -y -q "${missing[@]}"
