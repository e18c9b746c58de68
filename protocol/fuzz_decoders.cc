#include "protocol/fuzz_decoders.h"

#include <algorithm>
#include <cmath>

#include "common/status.h"
#include "protocol/color_codec.h"
#include "protocol/depth_codec.h"
#include "protocol/geometry2_codec.h"
#include "protocol/geometry_codec.h"
#include "protocol/messages.h"

namespace holo::protocol {

namespace {

// Lower limits keep a fuzz iteration's memory small; the code paths are the same.
Limits FuzzLimits() {
  Limits limits;
  limits.max_frame_payload = 1u << 20;
  limits.max_message_bytes = 2u << 20;
  limits.max_vertices = 1u << 18;
  limits.max_triangles = 1u << 19;
  limits.max_image_pixels = 1u << 20;
  return limits;
}

}  // namespace

int FuzzStream(std::span<const uint8_t> body) {
  const Limits limits = FuzzLimits();
  int decoded = 0;
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
  return decoded;
}

int FuzzMessage(std::span<const uint8_t> body) { return DecodeMessage(body, FuzzLimits()).ok() ? 1 : 0; }

int FuzzGeometry(std::span<const uint8_t> body) {
  Mesh mesh;
  if (!DecodeGeometry(body, &mesh, FuzzLimits()).ok()) return 0;
  HOLO_CHECK_MSG(CheckMesh(mesh).ok(), "decoded mesh does not validate");
  return 1;
}

int FuzzColor(std::span<const uint8_t> body) {
  const Limits limits = FuzzLimits();
  ImageRgb8 image;
  ImageGray8 mask;
  const bool ok = DecodeColor(body, &image, &mask, limits).ok();
  if (ok) HOLO_CHECK(image.width() == mask.width() && image.height() == mask.height());
  // A stream decoder that decoded the input before (and so clears only
  // the box it wrote) gives the same images as the fresh decode.
  thread_local ColorDecoder stream;
  HOLO_CHECK(stream.Decode(body, limits).ok() == ok);
  if (ok) HOLO_CHECK_MSG(stream.image() == image && stream.mask() == mask, "stream decode differs from a fresh one");
  return ok ? 1 : 0;
}

int FuzzPodFrame(std::span<const uint8_t> body) {
  const Limits limits = FuzzLimits();
  auto p = DecodePayload(MessageType::kPodFrame, body, limits);
  if (!p.ok()) return 0;
  const auto& f = std::get<PodFrame>(*p);
  int decoded = 1;
  ImageDepth16 depth;
  if (DecodeDepth(f.depth, &depth, limits).ok()) {  // D1 or D2, by the blob's codec byte
    int w = 0, h = 0;
    HOLO_CHECK(PeekDepthSize(f.depth, &w, &h).ok());
    HOLO_CHECK(depth.width() == w && depth.height() == h && w > 0 && h > 0);
    ++decoded;
  }
  ImageRgb8 image;
  ImageGray8 mask;
  if (DecodeColor(f.color, &image, &mask, limits).ok()) ++decoded;
  return decoded;
}

int FuzzRegions(std::span<const uint8_t> body) {
  auto p = DecodePayload(MessageType::kRegions, body, FuzzLimits());
  if (!p.ok()) return 0;
  const auto& m = std::get<Regions>(*p);
  HOLO_CHECK(m.regions.size() <= kMaxRegions);
  // Every accepted payload has exactly one encoding (no slack a decoder could misread).
  const std::vector<uint8_t> again = EncodePayload(m);
  HOLO_CHECK_MSG(std::equal(again.begin(), again.end(), body.begin(), body.end()),
                 "regions payload does not re-encode to the same bytes");
  return 1;
}

int FuzzLeanAudioPose(std::span<const uint8_t> payload) {
  Header h;
  h.type = MessageType::kAudioPose;
  h.sequence = 77;
  h.capture_time_us = 1700000000123456;
  auto p = DecodePayload(h, payload, FuzzLimits());
  if (!p.ok()) return 0;
  const auto& a = std::get<AudioPose>(*p);
  if (a.codec != AudioCodec::kOpusLean) return 1;
  HOLO_CHECK(a.sequence == h.sequence && a.capture_time_us == h.capture_time_us);
  HOLO_CHECK(a.channels == 1 && a.sample_rate == 48000 && a.duration_us_div10 == 2000);
  HOLO_CHECK(!a.audio.empty() && a.audio.size() <= 1275);
  for (float v : {a.pose.x, a.pose.y, a.pose.z}) HOLO_CHECK(std::isfinite(v) && std::fabs(v) <= 1000.0f);
  for (float v : {a.pose.yaw, a.pose.pitch, a.pose.roll}) HOLO_CHECK(std::isfinite(v) && std::fabs(v) <= 3.1416f);
  if (!a.has_pose) HOLO_CHECK(a.pose == HeadPose{});
  // What decodes encodes back to the same frame (quantization is idempotent).
  auto again = DecodeMessage(EncodeMessage(Header{}, a), FuzzLimits());
  HOLO_CHECK_MSG(again.ok(), "a decoded lean frame does not encode back");
  HOLO_CHECK_MSG(std::get<AudioPose>(again->payload) == a, "lean frame changes through encode + decode");
  return 2;
}

int FuzzGeometry2(std::span<const uint8_t> body) {
  const Limits limits = FuzzLimits();
  Geometry2Decoder decoder;
  Mesh mesh;
  int decoded = 0;
  bool had_keyframe = false;
  size_t off = 0;
  while (off < body.size()) {
    size_t n = body.size() - off;
    if (n >= 2) {
      const size_t len = body[off] | (size_t{body[off + 1]} << 8);
      off += 2;
      n = std::min(len, body.size() - off);
    }
    const std::span<const uint8_t> blob = body.subspan(off, n);
    off += n;
    if (!decoder.Decode(blob, &mesh, limits).ok()) {
      HOLO_CHECK_MSG(mesh.positions.empty() && mesh.triangles.empty(), "a refused G2 blob left a mesh behind");
      continue;
    }
    auto info = PeekGeometry2(blob);
    HOLO_CHECK(info.ok());
    HOLO_CHECK_MSG(info->keyframe || had_keyframe, "a predicted G2 frame decoded without a keyframe");
    had_keyframe |= info->keyframe;
    HOLO_CHECK_MSG(CheckMesh(mesh).ok(), "decoded G2 mesh does not validate");
    HOLO_CHECK(mesh.num_vertices() == info->num_vertices && mesh.normals.size() == mesh.num_vertices());
    ++decoded;
  }
  return decoded;
}

std::vector<uint8_t> Geometry2FuzzInput(const std::vector<std::vector<uint8_t>>& blobs) {
  std::vector<uint8_t> out;
  for (const auto& b : blobs) {
    HOLO_CHECK(b.size() < 65536);
    out.push_back(static_cast<uint8_t>(b.size()));
    out.push_back(static_cast<uint8_t>(b.size() >> 8));
    out.insert(out.end(), b.begin(), b.end());
  }
  return out;
}

int FuzzDecoders(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::span<const uint8_t> body(data + 1, size - 1);
  switch (static_cast<FuzzTarget>(data[0] % 4)) {
    case FuzzTarget::kStream: return FuzzStream(body);
    case FuzzTarget::kMessage: return FuzzMessage(body);
    case FuzzTarget::kGeometry: return FuzzGeometry(body);
    case FuzzTarget::kColor: return FuzzColor(body);
  }
  return 0;
}

std::vector<uint8_t> FuzzInput(FuzzTarget target, const std::vector<uint8_t>& body) {
  std::vector<uint8_t> out;
  out.reserve(body.size() + 1);
  out.push_back(static_cast<uint8_t>(target));
  out.insert(out.end(), body.begin(), body.end());
  return out;
}

}  // namespace holo::protocol
