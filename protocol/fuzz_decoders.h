// Fuzz entry points of the protocol decoders, one per decoder (the libFuzzer
// targets protocol/fuzz/fuzz_<decoder>.cc call them), and FuzzDecoders, which
// drives all of them from one input (the corpus-replay and mutation tests of
// tests/protocol/ and the combined target). FuzzDecoders' first byte selects
// the decoder, the rest is its input:
//   0 — byte stream: FrameParser (fed in uneven chunks) + MessageAssembler
//   1 — one whole message (DecodeMessage)
//   2 — a geometry blob (DecodeGeometry)
//   3 — a colour blob (DecodeColor)
// Anything a decoder accepts must also satisfy the invariants its callers
// rely on (a mesh that validates, images with matching mask); a violation
// aborts, so the fuzzer reports it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace holo::protocol {

enum class FuzzTarget : uint8_t { kStream = 0, kMessage = 1, kGeometry = 2, kColor = 3 };

// Each returns the number of items decoded successfully (for tests) and never
// crashes on any input.
int FuzzStream(std::span<const uint8_t> bytes);    // FrameParser (uneven chunks) + MessageAssembler
int FuzzMessage(std::span<const uint8_t> bytes);   // DecodeMessage
int FuzzGeometry(std::span<const uint8_t> bytes);  // DecodeGeometry (G0, G1, …)
int FuzzColor(std::span<const uint8_t> bytes);     // DecodeColor (C0, C1, …) and ColorDecoder
// A PodFrame payload (DecodePayload) and, when it decodes, its depth (D1 or
// D2) and colour blobs (DecodeDepth, DecodeColor). Not part of FuzzDecoders (whose
// selector byte and corpus stay as they are); its own libFuzzer target.
int FuzzPodFrame(std::span<const uint8_t> bytes);
// A Regions payload (DecodePayload of type 15); what it accepts must
// re-encode to the same bytes. Its own libFuzzer target (fuzz_regions).
int FuzzRegions(std::span<const uint8_t> bytes);
// An AudioPose payload under a fixed header (sequence 77, capture time
// 1700000000123456 µs), meant for the lean layout (codec 3, PROTOCOL.md §9.1):
// a lean frame that decodes must carry the header's sequence and time, a
// pose within ±1 km and ±π, an Opus packet of 1..1275 bytes, and encode
// back to a message that decodes to the same frame. Its own libFuzzer target
// (holoport-fuzz-lean-audio-pose), not part of FuzzDecoders. Returns 0
// (refused), 1 (a classic frame), 2 (a lean frame).
int FuzzLeanAudioPose(std::span<const uint8_t> bytes);
// A G2 geometry stream (protocol/geometry2_codec.h) through one fresh
// Geometry2Decoder: the input is a sequence of blobs, each `u16 length` +
// bytes (a short last one is fed as it is), so that keyframes and the
// predicted frames that follow them are reached. Anything accepted must be
// a mesh that passes CheckMesh with the header's vertex count; a predicted
// frame is never accepted before a keyframe. Its own libFuzzer target
// (holoport-fuzz-geometry2), not part of FuzzDecoders. Returns the number of
// blobs decoded.
int FuzzGeometry2(std::span<const uint8_t> bytes);
// The input format of FuzzGeometry2 for `blobs` (each < 64 KiB).
std::vector<uint8_t> Geometry2FuzzInput(const std::vector<std::vector<uint8_t>>& blobs);

int FuzzDecoders(const uint8_t* data, size_t size);

// `target` byte followed by `body`, the input format of FuzzDecoders.
std::vector<uint8_t> FuzzInput(FuzzTarget target, const std::vector<uint8_t>& body);

}  // namespace holo::protocol
