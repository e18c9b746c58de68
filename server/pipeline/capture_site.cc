#include "server/pipeline/capture_site.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <vector>

#include "common/clock.h"

namespace holo {

StatusOr<MaskSource> ParseMaskSource(const std::string& name) {
  if (name == "segment") return MaskSource::kSegment;
  if (name == "truth") return MaskSource::kTruth;
  if (name == "dataset") return MaskSource::kDataset;
  if (name == "none") return MaskSource::kNone;
  return InvalidArgument("masks must be one of segment, truth, dataset, none; got '" + name + "'");
}

const char* MaskSourceName(MaskSource m) {
  switch (m) {
    case MaskSource::kSegment: return "segment";
    case MaskSource::kTruth: return "truth";
    case MaskSource::kDataset: return "dataset";
    case MaskSource::kNone: return "none";
  }
  return "?";
}

Status CaptureSiteOptions::Check() const {
  if (background_frames < 1 || background_frames > 1000)
    return InvalidArgument("background_frames must be in [1, 1000], got " + std::to_string(background_frames));
  HOLO_RETURN_IF_ERROR(segment.Check().WithContext("segment"));
  HOLO_RETURN_IF_ERROR(depth_filter.Check().WithContext("depth filter"));
  HOLO_RETURN_IF_ERROR(tsdf.Check().WithContext("tsdf"));
  HOLO_RETURN_IF_ERROR(cleanup.Check().WithContext("cleanup"));
  HOLO_RETURN_IF_ERROR(texture_options.Check().WithContext("texture"));
  HOLO_RETURN_IF_ERROR(pipeline.Check().WithContext("pipeline"));
  if (stream_mesh) HOLO_RETURN_IF_ERROR(stream.Check().WithContext("stream mesh"));
  if (stream_field && !stream_mesh) return InvalidArgument("stream_field needs stream_mesh (the grid is the stream mesh's)");
  if (temporal) HOLO_RETURN_IF_ERROR(TemporalOptions().Check().WithContext("temporal"));
  if (hull) {
    if (temporal) return InvalidArgument("the visual hull is per frame: it cannot be combined with temporal fusion");
    if (masks == MaskSource::kNone) return InvalidArgument("the visual hull needs masks (segment, truth or dataset)");
    HOLO_RETURN_IF_ERROR(hull_options.Check().WithContext("visual hull"));
  }
  return OkStatus();
}

TemporalFusionOptions CaptureSiteOptions::TemporalOptions() const {
  TemporalFusionOptions o = temporal_options;
  o.tsdf = tsdf;
  o.cleanup = cleanup;
  return o;
}

CaptureSite::~CaptureSite() = default;

StatusOr<std::unique_ptr<CaptureSite>> CaptureSite::Create(FrameSource* source, FrameSource* background,
                                                           SyntheticStudio* studio, CaptureSiteOptions options) {
  if (source == nullptr) return InvalidArgument("capture site needs a frame source");
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_RETURN_IF_ERROR(source->rig().Check().WithContext("source rig"));
  std::unique_ptr<CaptureSite> site(new CaptureSite());
  site->rig_ = source->rig();
  site->options_ = options;
  site->source_ = source;
  site->studio_ = studio;
  if (options.masks == MaskSource::kTruth && studio == nullptr)
    return InvalidArgument("masks=truth needs the synthetic studio as the source");

  const bool need_background = options.masks == MaskSource::kSegment || options.color_calibration;
  if (need_background) {
    if (background == nullptr)
      return InvalidArgument(std::string("masks=") + MaskSourceName(options.masks) +
                             (options.color_calibration ? " with colour calibration" : "") +
                             " needs empty-room background frames");
    if (background->rig().pods.size() != site->rig_.pods.size())
      return InvalidArgument("background has " + std::to_string(background->rig().pods.size()) + " pods, source has " +
                             std::to_string(site->rig_.pods.size()));
    std::vector<RgbdFrameSet> empty;
    empty.reserve(static_cast<size_t>(options.background_frames));
    for (int i = 0; i < options.background_frames; ++i) {
      RgbdFrameSet f;
      Status s = background->Next(&f);
      if (s.code() == StatusCode::kOutOfRange) break;
      HOLO_RETURN_IF_ERROR(s.WithContext("background frame " + std::to_string(i)));
      empty.push_back(std::move(f));
    }
    if (empty.empty()) return InvalidArgument("background source delivered no frames");
    if (options.color_calibration) {
      HOLO_ASSIGN_OR_RETURN(ColorCalibration cal, EstimateColorCalibration(site->rig_, empty, 0));
      site->calibration_ = std::make_unique<ColorCalibration>(std::move(cal));
      for (auto& f : empty) site->calibration_->Apply(&f);
    }
    if (options.masks == MaskSource::kSegment) {
      site->segmenter_ = std::make_unique<Segmenter>(site->rig_, options.segment);
      for (const auto& f : empty) HOLO_RETURN_IF_ERROR(site->segmenter_->AddBackgroundFrame(f));
      HOLO_RETURN_IF_ERROR(site->segmenter_->FinishBackground());
    }
  }
  if (options.temporal) {
    HOLO_ASSIGN_OR_RETURN(site->temporal_, TemporalFusion::Create(options.TemporalOptions()));
  } else {
    TsdfOptions tsdf = options.tsdf;
    // The texture stage replaces every vertex colour: voxel colours would be
    // computed only to be thrown away (−4 CPU-ms per S8-QVGA frame).
    if (options.texture) tsdf.integrate_color = false;
    HOLO_ASSIGN_OR_RETURN(site->volume_, TsdfVolume::Create(tsdf));
    if (options.smooth_full_mesh && !options.hull) {
      HOLO_ASSIGN_OR_RETURN(site->smoothed_, TsdfVolume::Create(tsdf));
    }
    if (options.hull) {
      HOLO_ASSIGN_OR_RETURN(site->hull_, VisualHull::Create(options.hull_options));
    }
  }
  if (options.depth_filter.radius > 0 && !options.hull) {
    HOLO_ASSIGN_OR_RETURN(site->depth_filter_, DepthFilter::Create(options.depth_filter));
  }
  if (options.stream_mesh) {
    TsdfOptions tsdf = options.temporal ? options.TemporalOptions().tsdf : options.tsdf;
    if (options.texture && !options.temporal) tsdf.integrate_color = false;
    HOLO_ASSIGN_OR_RETURN(site->stream_, StreamMesher::Create(tsdf, options.stream));
  }
  if (options.texture) site->texturer_ = std::make_unique<Texturer>(site->rig_, options.texture_options);
  return site;
}

PipelineStages CaptureSite::MakeStages(std::function<Status(const FrameWork&)> sink,
                                       std::function<Status(FrameWork&)> encode) {
  PipelineStages st;
  // Ground-truth masks are rendered with the frame (same frame index).
  auto truth = std::make_shared<StudioGroundTruth>();
  st.acquire = [this, truth](FrameWork& w) -> Status {
    if (options_.masks == MaskSource::kTruth) {
      // Frames in acquisition order starting at the studio's current position.
      w.frames.frame_index = w.sequence;
      studio_->RenderFrame(w.sequence, &w.frames, truth.get());
      for (size_t p = 0; p < w.frames.frames.size(); ++p) w.frames.frames[p].mask = truth->mask[p];
    } else {
      // Frames of slots the pipeline skipped (drop_late_frames) are passed over.
      if (w.sequence > next_sequence_) HOLO_RETURN_IF_ERROR(source_->Skip(w.sequence - next_sequence_));
      next_sequence_ = w.sequence + 1;
      HOLO_RETURN_IF_ERROR(source_->Next(&w.frames));
      if (w.frames.frames.size() != rig_.pods.size())
        return DataLoss("frame set " + std::to_string(w.frames.frame_index) + " has " +
                        std::to_string(w.frames.frames.size()) + " pods, rig has " + std::to_string(rig_.pods.size()));
      if (options_.masks == MaskSource::kNone)
        for (auto& f : w.frames.frames) f.mask = ImageGray8();
      if (options_.masks == MaskSource::kDataset)
        for (size_t p = 0; p < w.frames.frames.size(); ++p)
          if (w.frames.frames[p].mask.empty())
            return DataLoss("masks=dataset but frame set " + std::to_string(w.frames.frame_index) + " pod " +
                            std::to_string(p) + " has no mask");
    }
    if (calibration_) calibration_->Apply(&w.frames);
    return OkStatus();
  };
  // Depth is filtered within the masks, so after segmentation.
  if (segmenter_ || depth_filter_)
    st.segment = [this](FrameWork& w) {
      if (segmenter_) HOLO_RETURN_IF_ERROR(segmenter_->Segment(&w.frames));
      if (depth_filter_) HOLO_RETURN_IF_ERROR(depth_filter_->Apply(&w.frames));
      return OkStatus();
    };
  st.fuse_mesh = [this](FrameWork& w) -> Status {
    // Process CPU splits into fuse and mesh only when the stages run one at a time.
    const bool cpu = options_.pipeline.serial;
    const double cpu0 = cpu ? ProcessCpuTimeMs() : 0;
    Stopwatch sw;
    w.full_mesh.Clear();
    if (temporal_) {
      // Tracking, warping and fusing count as fuse; marching cubes + clean-up as mesh.
      TemporalFrameStats ts;
      Mesh* full = stream_ ? &w.full_mesh : &w.mesh;
      HOLO_RETURN_IF_ERROR(temporal_->Process(rig_, w.frames, full, &ts));
      const double cpu_all = cpu ? ProcessCpuTimeMs() - cpu0 : 0;
      w.timings.fuse_ms = std::max(1e-6, ts.total_ms - ts.mesh_ms);
      w.timings.mesh_ms = std::max(1e-6, ts.mesh_ms);
      if (cpu) {
        // CPU split in the wall-time ratio (the stage's threads are not timed separately).
        const double share = ts.total_ms > 0 ? ts.mesh_ms / ts.total_ms : 0.0;
        w.timings.fuse_cpu_ms = std::max(1e-6, cpu_all * (1 - share));
        w.timings.mesh_cpu_ms = std::max(1e-6, cpu_all * share);
      }
      if (stream_) {
        const double cpu1 = cpu ? ProcessCpuTimeMs() : 0;
        sw.Restart();
        HOLO_RETURN_IF_ERROR(stream_->Make(temporal_->reference_volume(), &w.mesh, nullptr,
                                           options_.stream_field ? &w.stream_field : nullptr));
        w.timings.simplify_ms = std::max(1e-6, sw.ElapsedMs());
        if (cpu) w.timings.simplify_cpu_ms = std::max(1e-6, ProcessCpuTimeMs() - cpu1);
        if (!options_.full_mesh) w.full_mesh.Clear();
      }
      return OkStatus();
    }
    if (hull_) {
      HOLO_RETURN_IF_ERROR(hull_->Build(rig_, w.frames, volume_.get()));
    } else {
      volume_->Reset();
      HOLO_RETURN_IF_ERROR(volume_->Integrate(rig_, w.frames));
    }
    w.timings.fuse_ms = sw.ElapsedMs();
    const double cpu1 = cpu ? ProcessCpuTimeMs() : 0;
    sw.Restart();
    if (stream_) {
      // The stream mesh (coarse marching cubes + clean-up) counts as mesh, its
      // simplification to the budget as simplify.
      StreamMeshStats ss;
      HOLO_RETURN_IF_ERROR(stream_->Make(*volume_, &w.mesh, &ss, options_.stream_field ? &w.stream_field : nullptr));
      spdlog::trace("stream mesh: {} triangles from marching cubes, {} sent ({} short edges collapsed{}; {:.1f} ms)",
                    ss.coarse_triangles, ss.triangles, ss.collapses, ss.quadric ? ", then quadric" : "",
                    ss.simplify_ms);
      w.timings.mesh_ms = std::max(1e-6, ss.downsample_ms + ss.extract_ms);
      w.timings.simplify_ms = std::max(1e-6, ss.simplify_ms);
      if (cpu) {
        const double all = ProcessCpuTimeMs() - cpu1;
        const double wall = ss.downsample_ms + ss.extract_ms + ss.simplify_ms;
        const double share = wall > 0 ? ss.simplify_ms / wall : 0.0;
        w.timings.mesh_cpu_ms = std::max(1e-6, all * (1 - share));
        w.timings.simplify_cpu_ms = std::max(1e-6, all * share);
      }
      if (options_.full_mesh) {
        HOLO_RETURN_IF_ERROR(ExtractFullMesh(&w.full_mesh));
        HOLO_RETURN_IF_ERROR(CleanupMesh(options_.cleanup, &w.full_mesh));
      }
    } else {
      HOLO_RETURN_IF_ERROR(ExtractFullMesh(&w.mesh));
      HOLO_RETURN_IF_ERROR(CleanupMesh(options_.cleanup, &w.mesh));
      w.timings.mesh_ms = std::max(1e-6, sw.ElapsedMs());
      if (cpu) w.timings.mesh_cpu_ms = std::max(1e-6, ProcessCpuTimeMs() - cpu1);
    }
    if (cpu) w.timings.fuse_cpu_ms = std::max(1e-6, cpu1 - cpu0);
    return OkStatus();
  };
  if (texturer_)
    st.texture = [this](FrameWork& w) {
      HOLO_RETURN_IF_ERROR(texturer_->Apply(w.frames, &w.mesh));
      if (!w.full_mesh.empty()) HOLO_RETURN_IF_ERROR(texturer_->Apply(w.frames, &w.full_mesh));
      return OkStatus();
    };
  st.encode = std::move(encode);
  st.sink = std::move(sink);
  return st;
}

Status CaptureSite::ExtractFullMesh(Mesh* out) {
  if (smoothed_) {
    HOLO_RETURN_IF_ERROR(volume_->SmoothInto(smoothed_.get()));
    smoothed_->ExtractMesh(out);
  } else {
    volume_->ExtractMesh(out);
  }
  return OkStatus();
}

StatusOr<PipelineStats> CaptureSite::Run(std::function<Status(const FrameWork&)> sink,
                                         std::function<Status(FrameWork&)> encode) {
  pipeline_ = std::make_unique<Pipeline>(MakeStages(std::move(sink), std::move(encode)), options_.pipeline);
  return pipeline_->Run();
}

void CaptureSite::Stop() {
  if (pipeline_) pipeline_->Stop();
}

}  // namespace holo
