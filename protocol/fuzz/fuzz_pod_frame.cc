// libFuzzer target: protocol FuzzPodFrame (protocol/fuzz_decoders.h): a
// PodFrame payload and its depth (D1) and colour blobs.
#include <cstddef>
#include <cstdint>
#include <span>

#include "protocol/fuzz_decoders.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  holo::protocol::FuzzPodFrame(std::span<const uint8_t>(data, size));
  return 0;
}
