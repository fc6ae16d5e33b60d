// The rank estimators' fast ranking (ranking.cpp), shared with the M-estimators' ranking
// (distinct_values.cpp) and the bit-identity test's switch between its portable and AVX2 code.
// Private: mcstat::detail, not installed (cmake/Install.cmake leaves out every detail/ folder).
#pragma once

namespace mcstat {

namespace detail {
/// Test hook: with false, the rank estimators' fast path runs its portable code even on a CPU with
/// AVX2 (both versions give the same bits; the bit-identity test checks each). true restores the
/// CPU's choice. Returns the previous setting. Not thread-safe: call it between estimates.
bool setUseAvx2(bool on);
/// Whether the fast paths use their AVX2 code now (the CPU's choice, or setUseAvx2's); the
/// confidence intervals' passes follow it too.
bool usesAvx2();
/// For the M-estimators (myriad, meridian): order[r] = the position of the key of rank r, in the
/// order "key ascending, ties by position", for n <= 64 keys, none NaN. `key` must have room for n
/// rounded up to a multiple of 8 (the padding is overwritten). The rank estimators' fast ranking.
void rankKeys(double* key, int n, int* order);
}  // namespace detail

}  // namespace mcstat
