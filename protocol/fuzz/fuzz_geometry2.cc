// libFuzzer target: protocol FuzzGeometry2 (protocol/fuzz_decoders.h), a G2
// temporal geometry stream (length-prefixed blobs) through one decoder.
#include <cstddef>
#include <cstdint>
#include <span>

#include "protocol/fuzz_decoders.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  holo::protocol::FuzzGeometry2(std::span<const uint8_t>(data, size));
  return 0;
}
