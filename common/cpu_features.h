// What the CPU can do beyond the build's baseline, asked once per process.
// Code with AVX2 paths (segmentation's unary term, TSDF integration, the
// viewer's atlas bake) compiles them with __attribute__((target("avx2")))
// and takes them only where this says the CPU has AVX2.
#pragma once

namespace holo {

inline bool CpuHasAvx2() {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
#else
  return false;
#endif
}

}  // namespace holo
