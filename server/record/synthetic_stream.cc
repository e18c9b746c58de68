#include "server/record/synthetic_stream.h"

#include <cmath>
#include <numbers>

#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::record {

SyntheticStream::~SyntheticStream() = default;

StatusOr<std::unique_ptr<SyntheticStream>> SyntheticStream::Create(SyntheticStreamOptions options) {
  HOLO_RETURN_IF_ERROR(options.geometry.Check());
  if (options.audio_sample_rate < 8000 || options.audio_sample_rate > 48000 || options.audio_sample_rate % 50 != 0)
    return InvalidArgument("audio sample rate must be 8000..48000 and a multiple of 50 Hz");
  HOLO_ASSIGN_OR_RETURN(Workload w, GetWorkload(options.workload));
  StudioOptions so = w.studio;
  so.threads = 1;
  HOLO_ASSIGN_OR_RETURN(auto studio, SyntheticStudio::Create(w.rig, so));
  std::unique_ptr<SyntheticStream> s(new SyntheticStream());
  s->options_ = std::move(options);
  s->studio_ = std::move(studio);
  s->fps_ = so.fps;
  return s;
}

Status SyntheticStream::Next(StreamMessage* out) {
  protocol::Header h;
  if (!rig_sent_) {
    rig_sent_ = true;
    h.stream_id = 0;
    h.sequence = rig_seq_++;
    h.capture_time_us = 0;
    out->time_us = 0;
    out->type = protocol::MessageType::kRig;
    out->frame = protocol::EncodeMessage(h, protocol::RigMessage{studio_->rig()});
    return OkStatus();
  }
  const int64_t video_t = studio_->TimestampUs(next_video_);
  const int64_t audio_t = next_audio_ * 20000;
  if (options_.audio && audio_t < video_t) {
    protocol::AudioPose a;
    a.codec = protocol::AudioCodec::kPcm16;
    a.channels = 1;
    a.sample_rate = options_.audio_sample_rate;
    a.duration_us_div10 = 2000;
    a.sequence = audio_seq_;
    a.capture_time_us = audio_t;
    const double t = static_cast<double>(audio_t) * 1e-6;
    // The room frame is Z up (docs/audio.md): a head 1.6 m high circling the centre.
    a.pose.x = static_cast<float>(0.5 * std::cos(0.5 * t));
    a.pose.y = static_cast<float>(0.5 * std::sin(0.5 * t));
    a.pose.z = 1.6f;
    a.pose.yaw = static_cast<float>(std::remainder(0.5 * t, 2 * std::numbers::pi));
    const uint32_t n = a.sample_rate / 50;
    a.audio.resize(static_cast<size_t>(n) * 2);
    for (uint32_t i = 0; i < n; ++i) {
      const double ts = t + static_cast<double>(i) / a.sample_rate;
      const auto v = static_cast<int16_t>(std::lround(6000.0 * std::sin(2 * std::numbers::pi * 220.0 * ts)));
      a.audio[2 * i] = static_cast<uint8_t>(v & 0xFF);
      a.audio[2 * i + 1] = static_cast<uint8_t>((static_cast<uint16_t>(v) >> 8) & 0xFF);
    }
    h.stream_id = options_.audio_stream_id;
    h.sequence = audio_seq_++;
    h.capture_time_us = audio_t;
    out->time_us = audio_t;
    out->type = protocol::MessageType::kAudioPose;
    out->frame = protocol::EncodeMessage(h, a);
    ++next_audio_;
    return OkStatus();
  }
  const Mesh mesh = studio_->ForegroundMesh(next_video_);
  protocol::MeshFrame mf;
  mf.frame_index = next_video_;
  mf.codec = options_.geometry.codec;
  HOLO_RETURN_IF_ERROR(protocol::EncodeGeometry(mesh, options_.geometry, &mf.data));
  h.stream_id = options_.video_stream_id;
  h.sequence = mesh_seq_++;
  h.capture_time_us = video_t;
  h.flags = protocol::kFlagKeyFrame;
  out->time_us = video_t;
  out->type = protocol::MessageType::kMeshFrame;
  out->frame = protocol::EncodeMessage(h, mf);
  ++next_video_;
  return OkStatus();
}

}  // namespace holo::record
