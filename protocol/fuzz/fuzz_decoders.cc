// libFuzzer target over every protocol decoder at once (the first byte picks
// the decoder, see protocol/fuzz_decoders.h); corpus: tests/protocol/corpus.
#include <cstddef>
#include <cstdint>

#include "protocol/fuzz_decoders.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  holo::protocol::FuzzDecoders(data, size);
  return 0;
}
