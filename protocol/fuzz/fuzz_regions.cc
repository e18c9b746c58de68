// libFuzzer target: protocol FuzzRegions (protocol/fuzz_decoders.h): a
// Regions payload (message type 15). Seeds: protocol/fuzz/corpus/regions
// (written by tests/protocol/regions_message_test.cc).
#include <cstddef>
#include <cstdint>
#include <span>

#include "protocol/fuzz_decoders.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  holo::protocol::FuzzRegions(std::span<const uint8_t>(data, size));
  return 0;
}
