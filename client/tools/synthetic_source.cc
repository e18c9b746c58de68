#include "client/tools/synthetic_source.h"

#include "common/clock.h"
#include "common/rgbd.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "texture/texturer.h"

namespace holo::client {

SyntheticSource::~SyntheticSource() = default;

StatusOr<std::unique_ptr<SyntheticSource>> SyntheticSource::Create(const std::string& spec, int threads) {
  std::string name = "S8-QVGA";
  if (spec.rfind("synthetic", 0) != 0 || (spec.size() > 9 && spec[9] != ':')) {
    return InvalidArgument("unknown source '" + spec + "' (expected synthetic or synthetic:WORKLOAD)");
  }
  if (spec.size() > 10) name = spec.substr(10);
  auto workload = GetWorkload(name);
  if (!workload.ok()) return workload.status().WithContext("--source " + spec);
  std::unique_ptr<SyntheticSource> s(new SyntheticSource);
  s->workload_ = name;
  s->rig_ = workload->rig;
  s->fps_ = workload->studio.fps;
  StudioOptions options = workload->studio;
  // A server calibrates its pods' colours before sending the images.
  options.color_variation = false;
  // The viewer does not use the sensor depth; skip the noise model.
  options.depth_noise = false;
  options.threads = threads;
  HOLO_ASSIGN_OR_RETURN(s->studio_, SyntheticStudio::Create(s->rig_, options));
  TextureOptions texture_options;
  texture_options.threads = threads;
  HOLO_RETURN_IF_ERROR(texture_options.Check());
  s->texturer_ = std::make_unique<Texturer>(s->rig_, texture_options);
  s->frames_ = std::make_unique<RgbdFrameSet>();
  return s;
}

Status SyntheticSource::Produce(int64_t index, StreamFrame* out) {
  if (index < 0) return InvalidArgument("frame index must be >= 0");
  Stopwatch sw;
  out->index = index;
  out->capture_us = RealClock::Instance().NowUs();
  StudioGroundTruth gt;
  studio_->RenderFrame(index, frames_.get(), &gt);
  out->mesh = std::move(gt.foreground_mesh);
  out->mesh.colors.clear();
  HOLO_RETURN_IF_ERROR(texturer_->Apply(*frames_, &out->mesh));
  out->pod_images.resize(frames_->frames.size());
  for (size_t i = 0; i < frames_->frames.size(); ++i) out->pod_images[i] = frames_->frames[i].color;
  out->produce_ms = sw.ElapsedMs();
  return OkStatus();
}

}  // namespace holo::client
