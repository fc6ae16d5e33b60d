#!/usr/bin/env bash
# check_format.sh ROOT: every C++ file git tracks is as clang-format (ROOT/.clang-format) writes it
# (outside a git checkout: every *.cpp and *.h but the build trees'). Prints the files that are
# not, with the command that fixes them, and exits 1; 0 when all are. Run by CTest
# (architecture.format).
set -uo pipefail
cd "${1:?usage: check_format.sh ROOT}" || exit 2
command -v clang-format >/dev/null || { echo "check_format: clang-format not found (scripts/install-deps.sh)"; exit 1; }
files=()
while IFS= read -r -d '' f; do files+=("$f"); done < <(
  if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    git ls-files -z '*.cpp' '*.h'
  else  # a source tree without git (a release tarball): its C++ files but the build trees'
    find . \( -name 'build*' -prune \) -o \( -name '*.cpp' -o -name '*.h' \) -type f -print0
  fi)
# One clang-format for every file (a process per file spent 30 s starting them): its dry run names
# each file that is not clean in lines "FILE:LINE:COL: error: code should be clang-formatted".
report=$(clang-format --dry-run --Werror "${files[@]}" 2>&1 >/dev/null)
status=$?
bad=()
while IFS= read -r f; do [ -n "$f" ] && bad+=("$f"); done < <(
  printf '%s\n' "$report" | sed -n 's/^\(.*\):[0-9]*:[0-9]*: error: code should be clang-formatted.*/\1/p' |
    sort -u)
if [ "$status" -ne 0 ] && [ ${#bad[@]} -eq 0 ]; then  # failed, but not on a file's format
  printf '%s\n' "$report" | head -n 20
  echo "check_format: clang-format failed"
  exit 1
fi
if [ ${#bad[@]} -gt 0 ]; then
  printf '%s: not clang-format clean\n' "${bad[@]}"
  echo "fix: clang-format -i ${bad[*]}"
  exit 1
fi
