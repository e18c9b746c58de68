// A real protocol stream from the synthetic studio, made in-process: the Rig
// message, then per video frame the ground-truth foreground mesh (figures +
// props, per-vertex colour) encoded as a G1 (or G0) MeshFrame key frame, and
// 20 ms AudioPose frames of one participant (a PCM tone, head moving on a
// circle), interleaved in time order. What a capture site publishes, without
// running fusion; used by holoport-record --source synthetic and the tests.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/status.h"
#include "protocol/geometry_codec.h"
#include "protocol/messages.h"

namespace holo {
class SyntheticStudio;
}

namespace holo::record {

struct SyntheticStreamOptions {
  std::string workload = "S8-QVGA";
  protocol::GeometryEncodeOptions geometry;  // G1 by default
  bool audio = true;
  uint32_t audio_sample_rate = 16000;  // PCM s16 mono
  uint32_t video_stream_id = 1;
  uint32_t audio_stream_id = 2;
};

struct StreamMessage {
  int64_t time_us = 0;          // capture time = media time
  std::vector<uint8_t> frame;   // one unfragmented protocol frame
  protocol::MessageType type = protocol::MessageType::kPing;
};

class SyntheticStream {
 public:
  static StatusOr<std::unique_ptr<SyntheticStream>> Create(SyntheticStreamOptions options);
  ~SyntheticStream();
  // The next message in time order (the Rig first). Endless.
  Status Next(StreamMessage* out);
  double fps() const { return fps_; }
  const std::string& workload_name() const { return options_.workload; }

 private:
  SyntheticStream() = default;
  SyntheticStreamOptions options_;
  std::unique_ptr<SyntheticStudio> studio_;
  double fps_ = 30;
  bool rig_sent_ = false;
  int64_t next_video_ = 0;
  int64_t next_audio_ = 0;
  uint32_t rig_seq_ = 0, mesh_seq_ = 0, audio_seq_ = 0;
};

}  // namespace holo::record
