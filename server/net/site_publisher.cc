#include "server/net/site_publisher.h"
#include "common/clock.h"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <string>

#include <spdlog/spdlog.h>

namespace holo::net {
namespace {
double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

Status ReducedLayerOptions::Check() const {
  if (!(position_step_scale >= 1 && position_step_scale <= 16))
    return InvalidArgument("reduced layer: position_step_scale must be 1..16, got " + std::to_string(position_step_scale));
  if (jpeg_quality < 1 || jpeg_quality > 100)
    return InvalidArgument("reduced layer: jpeg_quality must be 1..100, got " + std::to_string(jpeg_quality));
  if (crf_offset < 0 || crf_offset > 51)
    return InvalidArgument("reduced layer: crf_offset must be 0..51, got " + std::to_string(crf_offset));
  if (frame_divisor < 1 || frame_divisor > 8)
    return InvalidArgument("reduced layer: frame_divisor must be 1..8, got " + std::to_string(frame_divisor));
  if (geometry_codec && *geometry_codec != protocol::GeometryCodec::kG1 && *geometry_codec != protocol::GeometryCodec::kG3)
    return InvalidArgument("reduced layer: geometry codec must be G1 or G3");
  if (color_codec && *color_codec != protocol::ColorCodec::kC1 && *color_codec != protocol::ColorCodec::kV1)
    return InvalidArgument("reduced layer: colour codec must be C1 or V1");
  return OkStatus();
}

LayerEncodeOptions EncodeOptionsOfLayer(const SitePublisherOptions& options, int layer) {
  LayerEncodeOptions o{options.geometry, options.surface, options.color_options, options.video};
  if (layer == 0) return o;
  o.geometry.position_step_m = static_cast<float>(options.geometry.position_step_m * options.reduced.position_step_scale);
  o.surface.position_step_m = static_cast<float>(std::min<double>(options.surface.position_step_m * options.reduced.position_step_scale, 0.1));
  o.color.jpeg_quality = options.reduced.jpeg_quality;
  const int crf = options.video.crf < 0 ? 24 : options.video.crf;
  o.video.crf = std::min(51, crf + options.reduced.crf_offset);
  if (options.reduced.geometry_codec) o.geometry.codec = *options.reduced.geometry_codec;
  if (options.reduced.color_codec) o.color.codec = *options.reduced.color_codec;
  return o;
}

bool PublisherNeedsField(const SitePublisherOptions& options) {
  return options.geometry.codec == protocol::GeometryCodec::kG3 ||
         (options.reduced.enabled && EncodeOptionsOfLayer(options, 1).geometry.codec == protocol::GeometryCodec::kG3);
}

SitePublisher::SitePublisher(Server* server, SitePublisherOptions options)
    : server_(server), options_(std::move(options)) {
  HOLO_CHECK(options_.reduced.Check().ok());
  needs_field_ = PublisherNeedsField(options_);
  HOLO_CHECK(!needs_field_ || options_.surface.Check().ok());
  server_->SetPublishedCodecs(options_.geometry.codec, options_.color_options.codec);
  for (int layer = 0; layer < 2; ++layer)
    static_cast<LayerEncodeOptions&>(layers_[layer]) = EncodeOptionsOfLayer(options_, layer);
  server_->SetLayerCodecs(1, layers_[1].geometry.codec, layers_[1].color.codec);
  if (options_.reduced.enabled) {
    server_->SetLayers(2);
    server_->SetLayerFrameStep(1, options_.reduced.frame_divisor);
  }
}

Status SitePublisher::Publish(int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh,
                              const std::vector<PodColor>& pods, PublishTimings* t, const SdfGrid* field) {
  HOLO_RETURN_IF_ERROR(Encode(frame_index, capture_wall_us, mesh, pods, &scratch_, field));
  PublishEncoded(&scratch_);
  *t = scratch_.timings;
  return OkStatus();
}

Status SitePublisher::Encode(int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh,
                             const std::vector<PodColor>& pods, EncodedFrame* out, const SdfGrid* field) {
  out->timings = PublishTimings{};
  if (needs_field_ && field == nullptr)
    return InvalidArgument("frame " + std::to_string(frame_index) + ": G3 geometry needs the stream mesh's grid");
  HOLO_RETURN_IF_ERROR(EncodeLayer(0, frame_index, capture_wall_us, mesh, field, pods, out));
  const int64_t n = frames_seen_++;
  // The reduced layer only while someone receives it (or is being moved to
  // it), on every frame_divisor-th frame.
  const bool wanted = options_.reduced.enabled && server_->ViewersOnLayer(1) > 0;
  if (!wanted) {
    out->reduced.clear();
    // A later start begins each pod's video with a key frame.
    layers_[1].video_encoders.clear();
    return OkStatus();
  }
  if (n % options_.reduced.frame_divisor != 0) {
    out->reduced.clear();
    return OkStatus();
  }
  out->reduced.resize(1);
  EncodedFrame& r = out->reduced[0];
  r.timings = PublishTimings{};
  HOLO_RETURN_IF_ERROR(EncodeLayer(1, frame_index, capture_wall_us, mesh, field, pods, &r));
  out->timings.reduced = true;
  out->timings.reduced_ms = r.timings.geometry_ms + r.timings.color_ms;
  out->timings.reduced_cpu_ms = r.timings.geometry_cpu_ms + r.timings.color_cpu_ms;
  out->timings.reduced_bytes = r.timings.geometry_bytes + r.timings.color_bytes;
  return OkStatus();
}

Status SitePublisher::EncodeLayer(int layer, int64_t frame_index, int64_t capture_wall_us, const Mesh& mesh,
                                  const SdfGrid* field, const std::vector<PodColor>& pods, EncodedFrame* out) {
  LayerState& st = layers_[layer];
  PublishTimings* t = &out->timings;
  out->layer = layer;
  out->frame_index = frame_index;
  out->capture_wall_us = capture_wall_us;
  // Geometry and colour are independent: encoded on two threads at once
  // (the frame's encode wall time is the longer of the two, not the sum).
  auto encode_geometry = [&]() -> Status {
    const auto t0 = std::chrono::steady_clock::now();
    const double cpu0 = holo::ThreadCpuTimeMs();
    protocol::GeometryEncodeOptions g = st.geometry;
    g.colors = g.colors && !mesh.colors.empty();
    out->codec = g.codec;
    out->geometry.clear();  // the encoder appends
    if (g.codec == protocol::GeometryCodec::kG3) {
      const Status s = protocol::EncodeSurface(*field, st.surface, &out->geometry);
      if (s.code() == StatusCode::kOutOfRange) {
        // A surface wider than G3's grid (two people far apart at a fine
        // step): this frame as G1 rather than none; the viewer decodes either.
        t->geometry_fallback = true;
        if (geometry_fallbacks_++ % 100 == 0)
          spdlog::warn("publisher: frame {} sent as G1: {} ({} such frames)", frame_index, s.message(),
                       geometry_fallbacks_);
        g.codec = protocol::GeometryCodec::kG1;
        out->codec = g.codec;
        out->geometry.clear();
        HOLO_RETURN_IF_ERROR(
            protocol::EncodeGeometry(mesh, g, &out->geometry).WithContext("frame " + std::to_string(frame_index)));
      } else {
        HOLO_RETURN_IF_ERROR(s.WithContext("frame " + std::to_string(frame_index)));
      }
    } else {
      HOLO_RETURN_IF_ERROR(
          protocol::EncodeGeometry(mesh, g, &out->geometry).WithContext("frame " + std::to_string(frame_index)));
    }
    t->geometry_ms = MsSince(t0);
    t->geometry_cpu_ms = holo::ThreadCpuTimeMs() - cpu0;
    t->geometry_bytes = out->geometry.size();
    return OkStatus();
  };
  protocol::ColorFrame& color = out->color;
  color.codec = st.color.codec;
  out->independent = true;
  // Keep the pod images' buffers for reuse; only the count changes.
  size_t used = 0;
  auto encode_color = [&]() -> Status {
    if (!options_.color) return OkStatus();
    const auto t0 = std::chrono::steady_clock::now();
    const double cpu0 = holo::ThreadCpuTimeMs();
    const bool video = st.color.codec == protocol::ColorCodec::kV1;
    bool force_keyframe = false;
    if (video) {
      // A viewer joined, lost a frame or is being moved to this layer: key
      // frames on every pod, but not more often than every 250 ms (a burst
      // of requests costs one).
      const uint64_t requests = server_->counters().layer_keyframe_requests[static_cast<size_t>(layer)];
      if (requests != st.keyframe_requests_seen && t0 - st.last_forced_keyframe >= std::chrono::milliseconds(250)) {
        st.keyframe_requests_seen = requests;
        st.last_forced_keyframe = t0;
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
        auto& enc = st.video_encoders[p.pod_id];
        if (enc == nullptr) {
          HOLO_ASSIGN_OR_RETURN(enc, protocol::VideoEncoder::Create(st.video));
        }
        if (force_keyframe) enc->RequestKeyframe();
        const int64_t keys = enc->keyframes();
        HOLO_RETURN_IF_ERROR(enc->Encode(*p.image, *p.mask, &pi.data).WithContext("pod " + std::to_string(p.pod_id)));
        all_keyframes = all_keyframes && enc->keyframes() > keys;
      } else {
        auto enc = st.color_encoders.try_emplace(p.pod_id, st.color).first;
        HOLO_RETURN_IF_ERROR(enc->second.Encode(*p.image, *p.mask, &pi.data));
      }
      t->color_bytes += pi.data.size();
    }
    t->color_keyframe = all_keyframes && used > 0;
    if (video && used > 0) out->independent = t->color_keyframe;
    t->color_ms = MsSince(t0);
    t->color_cpu_ms = holo::ThreadCpuTimeMs() - cpu0;
    return OkStatus();
  };
  Status status[2];
  pool_.Run(2, [&](int task, int) { status[task] = task == 0 ? encode_geometry() : encode_color(); });
  HOLO_RETURN_IF_ERROR(status[0]);
  HOLO_RETURN_IF_ERROR(status[1]);
  color.images.resize(used);
  ++encoded_[layer];
  return OkStatus();
}

void SitePublisher::PublishEncoded(EncodedFrame* frame) {
  const auto t0 = std::chrono::steady_clock::now();
  frame->timings.viewers = server_->num_viewers();
  auto publish = [&](const EncodedFrame& f) {
    server_->PublishVideo(MakeVideoFrame(f.frame_index, f.capture_wall_us, f.codec, f.geometry,
                                         f.color.images.empty() ? nullptr : &f.color,
                                         server_->config().fragment_bytes, kSiteStreamId, f.layer, f.independent));
  };
  publish(*frame);
  for (const EncodedFrame& r : frame->reduced) publish(r);
  frame->timings.publish_ms = MsSince(t0);
}

}  // namespace holo::net
