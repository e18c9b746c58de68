// One entry point that drives every decoder of the protocol with arbitrary
// bytes: the libFuzzer target (protocol/fuzz/) and the corpus-replay and
// mutation tests (tests/protocol/) call it. The first byte selects the
// decoder, the rest is its input:
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
#include <vector>

namespace holo::protocol {

enum class FuzzTarget : uint8_t { kStream = 0, kMessage = 1, kGeometry = 2, kColor = 3 };

// Returns the number of items decoded successfully (for tests); never crashes.
int FuzzDecoders(const uint8_t* data, size_t size);

// `target` byte followed by `body`, the input format of FuzzDecoders.
std::vector<uint8_t> FuzzInput(FuzzTarget target, const std::vector<uint8_t>& body);

}  // namespace holo::protocol
