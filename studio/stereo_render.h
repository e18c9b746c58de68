// Active stereo in the synthetic studio: per pod, a rectified near-infrared
// pair lit by the pod's speckle projector, with exact ground-truth disparity.
//
// Image model (per IR pixel, 2×2 supersampled by default so the pattern is
// not aliased): I = albedo · (ambient + power · pattern(u, v) · cosθ / r²),
// where (u, v) is the direction from the projector to the surface point, r
// its distance to the projector and cosθ the angle between the surface
// normal and the view ray; then read noise and shot noise, 8-bit
// quantisation. The pattern is a jittered dot grid (dot_pitch_mrad,
// dot_density), the same for pods with the same projector parameters. Simplifications, stated: one IR
// reflectance for every surface, each pod sees only its own projector, and
// projector shadows are not modelled (a surface seen by a camera is lit).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "common/image.h"
#include "common/rig.h"
#include "common/status.h"
#include "studio/studio.h"

namespace holo {

struct StereoRenderOptions {
  // IR light from elsewhere (lamps, windows) on a white surface, fraction of
  // the sensor's full scale.
  float ambient = 0.1f;
  // Near-infrared reflectance of every surface.
  float albedo = 0.8f;
  // Sensor noise, grey levels: read noise σ, and shot noise σ = shot · sqrt(I).
  float read_noise = 1.5f;
  float shot_noise = 0.25f;
  bool noise = true;
  // Samples per pixel side (1 = point samples; 2 = 2×2 box filter).
  int supersample = 2;
  uint64_t seed = 1;
  // OK, or InvalidArgument naming the field.
  Status Check() const;
};

// One pod's rectified IR pair at one frame.
struct StereoPair {
  int pod_id = 0;
  ImageGray8 left, right;
  // Ground truth in the left IR camera: disparity, pixels (x_left − x_right
  // = fx·baseline/z), 0 where no surface; and the foreground mask.
  ImageFloat disparity;
  ImageGray8 mask;
  double fx = 0, baseline_m = 0;
};

class StereoStudioRenderer {
 public:
  // `studio` is borrowed for the renderer's lifetime. `rig` is the studio's
  // rig with a stereo block on every pod (same pods and poses; see
  // WithStereoPods); InvalidArgument naming the pod otherwise.
  static StatusOr<std::unique_ptr<StereoStudioRenderer>> Create(SyntheticStudio* studio, Rig rig,
                                                                StereoRenderOptions options);
  const Rig& rig() const { return rig_; }
  ~StereoStudioRenderer();
  StereoStudioRenderer(const StereoStudioRenderer&) = delete;
  StereoStudioRenderer& operator=(const StereoStudioRenderer&) = delete;

  // Renders every pod's pair of frame `frame_index` into `pairs` (reusing
  // its buffers). Deterministic: same frame, options and seed → same bytes.
  void Render(int64_t frame_index, std::vector<StereoPair>* pairs);

  // Renders the pair of the pod at `pod_index` (0..rig().pods.size()-1) alone
  // (what a network pod captures, holoport-pod --depth stereo): the same bytes
  // Render gives that pod, at 1/N of the cost. A pod's views are set up on
  // its first render, so a renderer used for one pod holds only that pod's.
  void RenderPod(int64_t frame_index, int pod_index, StereoPair* pair);

  const StereoRenderOptions& options() const { return options_; }

 private:
  struct Impl;
  StereoStudioRenderer(SyntheticStudio* studio, Rig rig, StereoRenderOptions options);
  SyntheticStudio* studio_;
  Rig rig_;
  StereoRenderOptions options_;
  std::unique_ptr<Impl> impl_;
};

// Baseline of the studio's stereo pods when the rig gives none, metres.
constexpr double kDefaultStereoBaselineM = 0.15;

// `rig` with an IR pair on every pod that has none: IR intrinsics equal to
// the depth camera's (so stereo depth lands directly in the depth image),
// baseline `baseline_m`, default projector. Stereo pods are kept as they are.
Rig WithStereoPods(const Rig& rig, double baseline_m = kDefaultStereoBaselineM);

}  // namespace holo
