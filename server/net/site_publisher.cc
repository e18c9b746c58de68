#include "server/net/site_publisher.h"
#include "common/clock.h"

#include <time.h>

#include <chrono>

namespace holo::net {
namespace {
double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

SitePublisher::SitePublisher(Server* server, SitePublisherOptions options)
    : server_(server), options_(std::move(options)) {
  server_->SetPublishedCodecs(options_.geometry.codec, options_.color_options.codec);
}

Status SitePublisher::Publish(int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh,
                              const std::vector<PodColor>& pods, PublishTimings* t) {
  HOLO_RETURN_IF_ERROR(Encode(frame_index, capture_wall_us, mesh, pods, &scratch_));
  PublishEncoded(&scratch_);
  *t = scratch_.timings;
  return OkStatus();
}

Status SitePublisher::Encode(int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh,
                             const std::vector<PodColor>& pods, EncodedFrame* out) {
  PublishTimings* t = &out->timings;
  *t = PublishTimings{};
  out->frame_index = frame_index;
  out->capture_wall_us = capture_wall_us;
  auto t0 = std::chrono::steady_clock::now();
  double cpu0 = holo::ThreadCpuTimeMs();
  protocol::GeometryEncodeOptions g = options_.geometry;
  g.colors = g.colors && !mesh.colors.empty();
  out->codec = g.codec;
  out->geometry.clear();  // the encoder appends
  HOLO_RETURN_IF_ERROR(protocol::EncodeGeometry(mesh, g, &out->geometry).WithContext("frame " + std::to_string(frame_index)));
  t->geometry_ms = MsSince(t0);
  t->geometry_cpu_ms = holo::ThreadCpuTimeMs() - cpu0;
  t->geometry_bytes = out->geometry.size();
  protocol::ColorFrame& color = out->color;
  color.codec = options_.color_options.codec;
  // Keep the pod images' buffers for reuse; only the count changes.
  size_t used = 0;
  if (options_.color) {
    t0 = std::chrono::steady_clock::now();
    cpu0 = holo::ThreadCpuTimeMs();
    const bool video = options_.color_options.codec == protocol::ColorCodec::kV1;
    bool force_keyframe = false;
    if (video) {
      // A viewer joined or lost a frame: key frames on every pod, but not
      // more often than every 250 ms (a burst of requests costs one).
      const uint64_t requests = server_->counters().keyframe_requests;
      if (requests != keyframe_requests_seen_ && t0 - last_forced_keyframe_ >= std::chrono::milliseconds(250)) {
        keyframe_requests_seen_ = requests;
        last_forced_keyframe_ = t0;
        force_keyframe = true;
      }
    }
    bool all_keyframes = video;
    for (const PodColor& p : pods) {
      if (p.image == nullptr || p.mask == nullptr || p.mask->width() != p.image->width() ||
          p.mask->height() != p.image->height() || p.image->width() == 0)
        continue;
      if (color.images.size() <= used) color.images.emplace_back();
      protocol::PodImage& pi = color.images[used++];
      pi.pod_id = p.pod_id;
      pi.data.clear();
      if (video) {
        auto& enc = video_encoders_[p.pod_id];
        if (enc == nullptr) {
          HOLO_ASSIGN_OR_RETURN(enc, protocol::VideoEncoder::Create(options_.video));
        }
        if (force_keyframe) enc->RequestKeyframe();
        const int64_t keys = enc->keyframes();
        HOLO_RETURN_IF_ERROR(enc->Encode(*p.image, *p.mask, &pi.data).WithContext("pod " + std::to_string(p.pod_id)));
        all_keyframes = all_keyframes && enc->keyframes() > keys;
      } else {
        auto enc = color_encoders_.try_emplace(p.pod_id, options_.color_options).first;
        HOLO_RETURN_IF_ERROR(enc->second.Encode(*p.image, *p.mask, &pi.data));
      }
      t->color_bytes += pi.data.size();
    }
    t->color_keyframe = all_keyframes && used > 0;
    t->color_ms = MsSince(t0);
    t->color_cpu_ms = holo::ThreadCpuTimeMs() - cpu0;
  }
  color.images.resize(used);
  return OkStatus();
}

void SitePublisher::PublishEncoded(EncodedFrame* frame) {
  const auto t0 = std::chrono::steady_clock::now();
  frame->timings.viewers = server_->num_viewers();
  server_->PublishVideo(MakeVideoFrame(frame->frame_index, frame->capture_wall_us, frame->codec, frame->geometry,
                                       frame->color.images.empty() ? nullptr : &frame->color,
                                       server_->config().fragment_bytes));
  frame->timings.publish_ms = MsSince(t0);
}

}  // namespace holo::net
