#include "protocol/fuzz_decoders.h"

#include <algorithm>

#include "common/status.h"
#include "protocol/color_codec.h"
#include "protocol/geometry_codec.h"
#include "protocol/messages.h"

namespace holo::protocol {

int FuzzDecoders(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const auto target = static_cast<FuzzTarget>(data[0] % 4);
  const std::span<const uint8_t> body(data + 1, size - 1);
  // Lower limits keep a fuzz iteration's memory small; the code paths are the same.
  Limits limits;
  limits.max_frame_payload = 1u << 20;
  limits.max_message_bytes = 2u << 20;
  limits.max_vertices = 1u << 18;
  limits.max_triangles = 1u << 19;
  limits.max_image_pixels = 1u << 20;
  int decoded = 0;
  switch (target) {
    case FuzzTarget::kStream: {
      FrameParser parser(limits);
      MessageAssembler assembler(limits, 4);
      size_t off = 0, chunk = 1;
      while (off < body.size()) {
        const size_t n = std::min(chunk, body.size() - off);
        if (!parser.Feed(body.data() + off, n).ok()) break;
        off += n;
        chunk = chunk * 3 % 97 + 1;  // uneven split points
        Frame f;
        while (parser.Next(&f)) {
          bool complete = false;
          Message m;
          if (assembler.Add(std::move(f), &complete, &m).ok() && complete) ++decoded;
        }
      }
      break;
    }
    case FuzzTarget::kMessage: {
      auto m = DecodeMessage(body, limits);
      if (m.ok()) ++decoded;
      break;
    }
    case FuzzTarget::kGeometry: {
      Mesh mesh;
      if (DecodeGeometry(body, &mesh, limits).ok()) {
        HOLO_CHECK_MSG(CheckMesh(mesh).ok(), "decoded mesh does not validate");
        ++decoded;
      }
      break;
    }
    case FuzzTarget::kColor: {
      ImageRgb8 image;
      ImageGray8 mask;
      const bool ok = DecodeColor(body, &image, &mask, limits).ok();
      if (ok) {
        HOLO_CHECK(image.width() == mask.width() && image.height() == mask.height());
        ++decoded;
      }
      // A stream decoder that decoded the input before (and so clears only
      // the box it wrote) gives the same images as the fresh decode.
      thread_local ColorDecoder stream;
      HOLO_CHECK(stream.Decode(body, limits).ok() == ok);
      if (ok) HOLO_CHECK_MSG(stream.image() == image && stream.mask() == mask, "stream decode differs from a fresh one");
      break;
    }
  }
  return decoded;
}

std::vector<uint8_t> FuzzInput(FuzzTarget target, const std::vector<uint8_t>& body) {
  std::vector<uint8_t> out;
  out.reserve(body.size() + 1);
  out.push_back(static_cast<uint8_t>(target));
  out.insert(out.end(), body.begin(), body.end());
  return out;
}

}  // namespace holo::protocol
