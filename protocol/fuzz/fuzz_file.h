// Helper for fuzz targets whose parser reads a file: writes the input to one
// per-process file under /dev/shm (memory) and returns its path.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include <unistd.h>

namespace holo::fuzz {

inline std::string WriteInputFile(const uint8_t* data, size_t size, const char* suffix) {
  static const std::string path =
      std::string("/dev/shm/holoport-fuzz-") + std::to_string(getpid()) + suffix;
  FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

}  // namespace holo::fuzz
