// libFuzzer target: protocol FuzzStream (protocol/fuzz_decoders.h) on raw bytes.
#include <cstddef>
#include <cstdint>
#include <span>

#include "protocol/fuzz_decoders.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  holo::protocol::FuzzStream(std::span<const uint8_t>(data, size));
  return 0;
}
