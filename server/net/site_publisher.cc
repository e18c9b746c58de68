#include "server/net/site_publisher.h"

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
  *t = PublishTimings{};
  auto t0 = std::chrono::steady_clock::now();
  protocol::GeometryEncodeOptions g = options_.geometry;
  g.colors = g.colors && !mesh.colors.empty();
  geometry_.clear();  // the encoder appends
  HOLO_RETURN_IF_ERROR(protocol::EncodeGeometry(mesh, g, &geometry_).WithContext("frame " + std::to_string(frame_index)));
  t->geometry_ms = MsSince(t0);
  t->geometry_bytes = geometry_.size();
  protocol::ColorFrame color;
  color.codec = options_.color_options.codec;
  if (options_.color) {
    t0 = std::chrono::steady_clock::now();
    for (const PodColor& p : pods) {
      if (p.image == nullptr || p.mask == nullptr || p.mask->width() != p.image->width() ||
          p.mask->height() != p.image->height() || p.image->width() == 0)
        continue;
      protocol::PodImage pi;
      pi.pod_id = p.pod_id;
      pi.data.clear();
      auto enc = color_encoders_.try_emplace(p.pod_id, options_.color_options).first;
      HOLO_RETURN_IF_ERROR(enc->second.Encode(*p.image, *p.mask, &pi.data));
      t->color_bytes += pi.data.size();
      color.images.push_back(std::move(pi));
    }
    t->color_ms = MsSince(t0);
  }
  t0 = std::chrono::steady_clock::now();
  t->viewers = server_->num_viewers();
  server_->PublishVideo(MakeVideoFrame(frame_index, capture_wall_us, g.codec, geometry_,
                                       color.images.empty() ? nullptr : &color, server_->config().fragment_bytes));
  t->publish_ms = MsSince(t0);
  return OkStatus();
}

}  // namespace holo::net
