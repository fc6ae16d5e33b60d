#!/usr/bin/env bash
# check_format.sh ROOT: every C++ file git tracks is as clang-format (ROOT/.clang-format) writes it
# (outside a git checkout: every *.cpp and *.h but the build trees'). Prints the files that are
# not, with the command that fixes them, and exits 1; 0 when all are. Run by CTest
# (architecture.format).
set -uo pipefail
cd "${1:?usage: check_format.sh ROOT}" || exit 2
command -v clang-format >/dev/null || { echo "check_format: clang-format not found (scripts/install-deps.sh)"; exit 1; }
bad=()
while IFS= read -r -d '' f; do
  clang-format --dry-run --Werror "$f" >/dev/null 2>&1 || bad+=("$f")
done < <(if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  git ls-files -z '*.cpp' '*.h'
else  # a source tree without git (a release tarball): its C++ files but the build trees'
  find . \( -name 'build*' -prune \) -o \( -name '*.cpp' -o -name '*.h' \) -type f -print0
fi)
if [ ${#bad[@]} -gt 0 ]; then
  printf '%s: not clang-format clean\n' "${bad[@]}"
  echo "fix: clang-format -i ${bad[*]}"
  exit 1
fi
