// libFuzzer entry point over every protocol decoder (see fuzz_decoders.h).
#include <cstddef>
#include <cstdint>

#include "protocol/fuzz_decoders.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  holo::protocol::FuzzDecoders(data, size);
  return 0;
}
