// What the processor offers beyond x86-64's baseline, asked once: the code paths compiled with
// __attribute__((target(...))) run only where these say yes, and give the portable paths' bits.
#pragma once

namespace mcstat {

/// Whether the processor runs AVX (eight-float registers).
inline bool cpuHasAvx() {
    static const bool on = (__builtin_cpu_init(), __builtin_cpu_supports("avx") != 0);
    return on;
}

/// Whether the processor runs AVX2 (integer and double lanes, gathers).
inline bool cpuHasAvx2() {
    static const bool on = (__builtin_cpu_init(), __builtin_cpu_supports("avx2") != 0);
    return on;
}

}  // namespace mcstat
