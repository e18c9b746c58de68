// The synthetic studio: a deterministic, procedurally animated scene (an
// articulated figure or two, a moving prop, a textured room, one light that
// casts shadows) rendered from every pod of a rig, with an active-stereo
// depth noise model and exact ground truth. It is the default input of every
// stage and the yardstick of every benchmark.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/camera.h"
#include "common/frame_source.h"
#include "common/image.h"
#include "common/mesh.h"
#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"

namespace holo {

class WorkerPool;
namespace studio {
struct SceneTemplate;
struct FrameScene;
}  // namespace studio

struct DepthNoiseOptions {
  // Axial noise σ at 1 m, millimetres; σ grows with z² (σ(z) = σ1·z²).
  float sigma_at_1m_mm = 3.0f;
  // Pixels whose surface is seen at more than this angle from the normal
  // drop out (depth 0), with probability ramping up over the last 10°.
  float grazing_dropout_deg = 78.0f;
  // Pixels next to a depth edge larger than this get a mixed ("flying")
  // depth between the two surfaces with probability `flying_pixel_prob`.
  float flying_edge_mm = 60.0f;
  float flying_pixel_prob = 0.5f;
  // Random dropouts anywhere (speckle), probability per pixel.
  float random_dropout_prob = 0.002f;
  // Depth beyond this is invalid (sensor range), metres.
  float max_range_m = 6.0f;
  Status Check() const;
};

struct StudioOptions {
  // Seed of every random choice (noise, colour variations); same seed and
  // options → byte-identical frames.
  uint64_t seed = 1;
  // Articulated figures (1 or 2) and props (0..2).
  int num_figures = 1;
  int num_props = 1;
  double fps = 30.0;
  // Render the room alone, for background learning.
  bool empty_room = false;
  // Apply the depth noise model (off: depth equals ground truth).
  bool depth_noise = true;
  DepthNoiseOptions noise;
  // Per-pod colour gain/offset differences (what colour calibration fixes).
  bool color_variation = true;
  // Worker threads for rendering (0 = hardware concurrency).
  int threads = 0;
  Status Check() const;
};

// Exact truth of one frame.
struct StudioGroundTruth {
  int64_t frame_index = 0;
  int64_t timestamp_us = 0;
  std::vector<ImageDepth16> depth;  // noise-free depth per pod (depth camera), mm
  std::vector<ImageGray8> mask;     // exact foreground (figures + props) per pod, 255 = foreground
  // Foreground surface (figures and props) in world coordinates. Same vertex
  // count and triangles every frame: vertex i of frame t and of frame t+1 are
  // the same material point, so the true motion of every point is known.
  Mesh foreground_mesh;
};

// A moment of the studio's animation that a viewer could hear: a foot of the
// first figure landing as it walks in place (every 0.65 s), or the ball
// touching the floor (every 1.05 s). The site's synthetic voice starts a
// syllable or a knock at each, so that voice and picture can be checked
// against each other (holoport-server --voice synthetic).
struct StudioSoundEvent {
  enum Kind : int { kFootfall = 0, kBounce = 1 };
  double time_s = 0;  // studio time (frame_index / fps)
  Kind kind = kFootfall;
};

class SyntheticStudio final : public FrameSource {
 public:
  // `rig` must pass Rig::Check and `options` StudioOptions::Check (HOLO_CHECK otherwise;
  // use Create for untrusted values).
  SyntheticStudio(Rig rig, StudioOptions options);
  ~SyntheticStudio() override;
  SyntheticStudio(const SyntheticStudio&) = delete;
  SyntheticStudio& operator=(const SyntheticStudio&) = delete;

  static StatusOr<std::unique_ptr<SyntheticStudio>> Create(Rig rig, StudioOptions options);

  // Renders frame `frame_index` of every pod into `frames` (reusing its
  // buffers) and, if `gt` is not null, its ground truth.
  void RenderFrame(int64_t frame_index, RgbdFrameSet* frames, StudioGroundTruth* gt);

  // Renders frame `frame_index` of the pod at `pod_index` alone (what a pod
  // process captures): the same pixels RenderFrame gives that pod, at 1/N
  // of the cost.
  void RenderPod(int64_t frame_index, int pod_index, RgbdFrame* out);

  // The foreground mesh (world coordinates, per-vertex colour) at `frame_index`.
  Mesh ForegroundMesh(int64_t frame_index) const;
  // Ground-truth render of the whole scene from any camera: noise-free colour
  // (no per-pod colour variation), depth in mm and foreground mask. Any
  // output may be null.
  void RenderView(int64_t frame_index, const CameraModel& camera, ImageRgb8* color, ImageDepth16* depth,
                  ImageGray8* mask) const;

  // Capture timestamp of a frame, µs (frame_index / fps).
  int64_t TimestampUs(int64_t frame_index) const;

  // Sound events with studio time in [t0_s, t1_s), in time order (none in
  // the empty room).
  std::vector<StudioSoundEvent> SoundEvents(double t0_s, double t1_s) const;
  // Where the head of figure `figure` is at studio time `t_s` (world frame;
  // origin at the head's centre, x forward through the face, y left, z up);
  // identity if there is no such figure.
  Pose HeadPose(double t_s, int figure = 0) const;

  // FrameSource: an endless live source starting at frame 0.
  const Rig& rig() const override { return rig_; }
  Status Next(RgbdFrameSet* out) override;
  int64_t num_frames() const override { return -1; }
  Status Seek(int64_t index) override;
  // Passes over `n` frames without rendering them (a camera's skipped frames
  // cost nothing).
  Status Skip(int64_t n) override;

  const StudioOptions& options() const { return options_; }

  // For renderers built on the studio (studio/stereo_render.h): poses
  // frame `frame_index` (cached between calls) and calls `fn` with the posed
  // scene and the studio's worker pool, on the calling thread.
  using PosedFrameFn =
      std::function<void(const studio::SceneTemplate& tmpl, const studio::FrameScene& scene, WorkerPool* pool)>;
  void WithPosedFrame(int64_t frame_index, const PosedFrameFn& fn);

 private:
  struct Impl;
  void RenderPodInto(int i, int worker, int64_t frame_index, RgbdFrame* out, ImageDepth16* gt_depth,
                     ImageGray8* gt_mask);
  Rig rig_;
  StudioOptions options_;
  std::unique_ptr<Impl> impl_;
  int64_t next_frame_ = 0;
};

}  // namespace holo
