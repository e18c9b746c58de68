// libFuzzer target: protocol FuzzPodFrame (protocol/fuzz_decoders.h): a
// PodFrame payload and its depth (D1 or D2) and colour blobs. Seeds:
// protocol/fuzz/corpus/pod_frame (written by tests/protocol/fuzz_corpus_test.cc).
#include <cstddef>
#include <cstdint>
#include <span>

#include "protocol/fuzz_decoders.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  holo::protocol::FuzzPodFrame(std::span<const uint8_t>(data, size));
  return 0;
}
