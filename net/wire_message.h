// Messages encoded once for every receiver. The capture pipeline publishes
// each frame ONCE as bytes (header + payload frames, fragmented when large);
// every viewer's send queue holds shared pointers to the same bytes.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "protocol/messages.h"

namespace holo::net {

// Content bits of Control.subscribe (PROTOCOL.md §4 Control).
inline constexpr uint32_t kContentGeometry = 1;
inline constexpr uint32_t kContentColor = 2;
inline constexpr uint32_t kContentAudio = 4;
inline constexpr uint32_t kContentRegions = 8;  // only on request: value 0 ("all") does not include it
inline constexpr uint32_t kContentAll = 7;
inline constexpr uint32_t kContentKnown = 15;

// Stream ids: 0 session control, 1 the site's capture (mesh + colour),
// 2 the voice of the person the site captures (holoport-server --voice),
// 256 + n the audio+pose of the site's n-th publisher connection.
inline constexpr uint32_t kSiteStreamId = 1;
inline constexpr uint32_t kSiteVoiceStreamId = 2;
inline constexpr uint32_t kFirstParticipantStreamId = 256;

// The content bit a message type needs (0: always delivered).
uint32_t ContentBitOf(protocol::MessageType type);

struct WireMessage {
  protocol::MessageType type = protocol::MessageType::kPing;
  uint32_t stream_id = 0;
  int64_t capture_time_us = 0;
  std::vector<uint8_t> bytes;         // frames back to back (header + payload each)
  std::vector<uint32_t> frame_ends;   // end offset of every frame in `bytes`
  size_t payload_bytes = 0;           // the message's payload (all fragments)
  // A lean AudioPose (codec 3, PROTOCOL.md §9.1) also in the classic layout
  // (codec 2), for receivers that did not negotiate the lean one; else null.
  std::shared_ptr<const WireMessage> classic_audio;
};
using WireMessagePtr = std::shared_ptr<const WireMessage>;

// Encodes `payload` with `header` (type and length derived; for a lean
// AudioPose also sequence and capture time: protocol::BindHeaderToPayload)
// into frames of at most `fragment_bytes` payload each.
WireMessagePtr MakeWireMessage(protocol::Header header, const protocol::Payload& payload, size_t fragment_bytes);
// The same from already encoded payload bytes; `header.type` must be set.
WireMessagePtr MakeWireMessageFromBytes(protocol::Header header, std::span<const uint8_t> payload,
                                        size_t fragment_bytes);

// `lean` (an encoded lean AudioPose message) with `classic`, the same frame in
// the classic layout, attached as its `classic_audio`.
WireMessagePtr WithClassicAudio(const WireMessagePtr& lean, WireMessagePtr classic);

// One video frame: its MeshFrame and (optional) ColorFrame. Queues hold and
// drop frames as a whole.
struct VideoFrame {
  int64_t frame_index = 0;
  int64_t capture_time_us = 0;
  // The site's quality layer (0 = full; net/layer_control.h), and whether
  // every part decodes without earlier frames (G1/C1 always; V1 only when
  // every pod's image is a key frame): a viewer changes layer only there.
  int layer = 0;
  bool independent = true;
  std::vector<WireMessagePtr> parts;
  size_t bytes() const;
};
using VideoFramePtr = std::shared_ptr<const VideoFrame>;

// Builds a video frame on `stream_id` (sequence = frame index) from a
// geometry blob (geometry_codec.h) and optional colour images.
// `color` may be null. `layer` and `independent` as in VideoFrame.
VideoFramePtr MakeVideoFrame(int64_t frame_index, int64_t capture_time_us, protocol::GeometryCodec codec,
                             std::span<const uint8_t> geometry_blob, const protocol::ColorFrame* color,
                             size_t fragment_bytes, uint32_t stream_id = kSiteStreamId, int layer = 0,
                             bool independent = true);

// Wall-clock time (system clock), µs since the Unix epoch: capture stamps on
// the wire and receive stamps, comparable across processes of one machine
// (and across machines up to their clock offset, which pings estimate).
int64_t WallUs();

}  // namespace holo::net
