#include "net/wire_message.h"

#include <algorithm>
#include <cstring>

#include "common/clock.h"

namespace holo::net {

using protocol::Header;
using protocol::kHeaderSize;
using protocol::MessageType;

uint32_t ContentBitOf(MessageType type) {
  switch (type) {
    case MessageType::kMeshFrame: return kContentGeometry;
    case MessageType::kColorFrame: return kContentColor;
    case MessageType::kAudioPose: return kContentAudio;
    case MessageType::kRegions: return kContentRegions;
    default: return 0;
  }
}

WireMessagePtr MakeWireMessageFromBytes(Header header, std::span<const uint8_t> payload, size_t fragment_bytes) {
  HOLO_CHECK(fragment_bytes > 0);
  auto m = std::make_shared<WireMessage>();
  m->type = header.type;
  m->stream_id = header.stream_id;
  m->capture_time_us = header.capture_time_us;
  m->payload_bytes = payload.size();
  const size_t frames = payload.empty() ? 1 : (payload.size() + fragment_bytes - 1) / fragment_bytes;
  m->bytes.resize(payload.size() + frames * kHeaderSize);
  m->frame_ends.reserve(frames);
  size_t off = 0, out = 0;
  do {
    const size_t n = std::min(fragment_bytes, payload.size() - off);
    Header h = header;
    h.payload_length = static_cast<uint32_t>(n);
    h.flags = static_cast<uint16_t>((header.flags & ~protocol::kFlagMoreFragments) |
                                    (off + n < payload.size() ? protocol::kFlagMoreFragments : 0));
    protocol::EncodeHeader(h, m->bytes.data() + out);
    if (n > 0) std::memcpy(m->bytes.data() + out + kHeaderSize, payload.data() + off, n);
    out += kHeaderSize + n;
    off += n;
    m->frame_ends.push_back(static_cast<uint32_t>(out));
  } while (off < payload.size());
  HOLO_CHECK(out == m->bytes.size());
  return m;
}

WireMessagePtr MakeWireMessage(Header header, const protocol::Payload& payload, size_t fragment_bytes) {
  protocol::BindHeaderToPayload(payload, &header);
  const std::vector<uint8_t> body = protocol::EncodePayload(payload);
  return MakeWireMessageFromBytes(header, body, fragment_bytes);
}

WireMessagePtr WithClassicAudio(const WireMessagePtr& lean, WireMessagePtr classic) {
  auto m = std::make_shared<WireMessage>(*lean);
  m->classic_audio = std::move(classic);
  return m;
}

size_t VideoFrame::bytes() const {
  size_t n = 0;
  for (const auto& p : parts) n += p->bytes.size();
  return n;
}

VideoFramePtr MakeVideoFrame(int64_t frame_index, int64_t capture_time_us, protocol::GeometryCodec codec,
                             std::span<const uint8_t> geometry_blob, const protocol::ColorFrame* color,
                             size_t fragment_bytes, uint32_t stream_id, int layer, bool independent) {
  auto f = std::make_shared<VideoFrame>();
  f->frame_index = frame_index;
  f->layer = layer;
  f->independent = independent;
  f->capture_time_us = capture_time_us;
  Header h;
  h.stream_id = stream_id;
  h.sequence = static_cast<uint32_t>(frame_index);
  h.capture_time_us = capture_time_us;
  // KEY_FRAME only where the whole frame decodes alone: recordings and live
  // segments seek and start there.
  h.flags = independent ? protocol::kFlagKeyFrame : 0;
  // MeshFrame payload: i64 frame_index · u8 codec · blob32 data, written
  // straight into one buffer (no intermediate copy of the blob).
  {
    std::vector<uint8_t> body;
    body.reserve(8 + 1 + 4 + geometry_blob.size());
    const uint64_t fi = static_cast<uint64_t>(frame_index);
    for (int i = 0; i < 8; ++i) body.push_back(static_cast<uint8_t>(fi >> (8 * i)));
    body.push_back(static_cast<uint8_t>(codec));
    const uint32_t n = static_cast<uint32_t>(geometry_blob.size());
    for (int i = 0; i < 4; ++i) body.push_back(static_cast<uint8_t>(n >> (8 * i)));
    body.insert(body.end(), geometry_blob.begin(), geometry_blob.end());
    h.type = MessageType::kMeshFrame;
    f->parts.push_back(MakeWireMessageFromBytes(h, body, fragment_bytes));
  }
  if (color != nullptr) {
    protocol::ColorFrame c = *color;
    c.frame_index = frame_index;
    f->parts.push_back(MakeWireMessage(h, c, fragment_bytes));
  }
  return f;
}

int64_t WallUs() { return WallClock::Instance().NowUs(); }

}  // namespace holo::net
