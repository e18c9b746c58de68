// Fuzz entry point of the V1 video colour decoder (protocol/video_codec.h),
// alongside the other decoders' in fuzz_decoders.h: the libFuzzer target
// holoport-fuzz-video (protocol/fuzz/fuzz_video_main.cc) and the codec tests
// call it. The input is one V1 blob. A decoder kept from call to call (per
// thread) sees the inputs as one stream, so a keyframe followed by its delta
// frames reaches the inter-frame paths; a fresh decoder sees each input alone.
// Anything accepted must give an image and a mask of the header's size; a
// violation aborts, so the fuzzer reports it.
#pragma once

#include <cstddef>
#include <cstdint>

namespace holo::protocol {

// Returns the number of decoders (0..2) that accepted the input; never crashes.
int FuzzVideoDecoder(const uint8_t* data, size_t size);

}  // namespace holo::protocol
