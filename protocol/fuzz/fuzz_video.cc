// libFuzzer entry point over the V1 video colour decoder (see fuzz_video.h).
#include <cstddef>
#include <cstdint>

#include "protocol/fuzz_video.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  holo::protocol::FuzzVideoDecoder(data, size);
  return 0;
}
