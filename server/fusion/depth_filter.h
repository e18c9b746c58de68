// Edge-preserving smoothing of the pods' depth before fusion.
//
// A time-of-flight or structured-light depth camera's axial noise grows with
// the square of the distance (σ ≈ 19 mm at 2.5 m in the studio's model, 3 mm
// at 1 m). Fused as it is, that noise folds the surface: every fine voxel
// sees one or two samples per pod, so the full-resolution S8-QVGA mesh is
// bumpy (148 k triangles, 5.5 mm mean distance to the truth) and full of
// small holes where a noisy sample carved free space. KinectFusion and
// Holoportation both smooth each depth map before fusing it, with a bilateral
// filter; this is the same idea in its cheapest form:
//
//   d'(p) = mean of d(q) over the (2r+1)² window around p, taking only the
//           q that belong to the foreground mask, have depth, and lie within
//           range_sigmas · σ(d(p)) of d(p), σ(z) = sigma_at_1m_mm · z².
//
// The range test keeps depth edges (another body part in front, the
// silhouette) from blending; the mask keeps the background out. A box window
// with a hard range test rather than Gaussian weights: on the studio frame
// 12 (exact masks) r = 2 with 3 σ gave the lowest Chamfer of the variants
// tried (r 1–4, 2–6 σ; docs/fusion.md, "Depth filter and smoothing"), and the integer
// window sums vectorise.
//
// Only foreground pixels are written; the others keep their depth. Written
// here rather than taken from OpenCV: cv::bilateralFilter has no mask and a
// range kernel independent of depth, and the site only pays for the person's
// pixels (its bounding box), not the whole image.
#pragma once

#include <memory>
#include <vector>

#include "common/rgbd.h"
#include "common/status.h"

namespace holo {

class WorkerPool;

struct DepthFilterOptions {
  // Window radius in pixels; 0 turns the filter off.
  int radius = 2;
  // A neighbour counts if its depth is within this many σ(z) of the centre's.
  float range_sigmas = 3.0f;
  // The sensor's axial noise at 1 m, millimetres (σ grows with z²).
  float sigma_at_1m_mm = 3.0f;
  // Worker threads over pods; 0 = all cores.
  int threads = 2;
  // OK, or InvalidArgument naming the field: "depth filter radius must be in [0, 4], got 7".
  Status Check() const;
};

class DepthFilter {
 public:
  static StatusOr<std::unique_ptr<DepthFilter>> Create(DepthFilterOptions options);
  ~DepthFilter();

  // Filters every pod's depth in place (its mask, when not empty, says which
  // pixels are the person). DataLoss naming the pod if a non-empty mask's
  // size differs from the depth image's; the frames are unchanged then.
  Status Apply(RgbdFrameSet* frames);

  // One image: what Apply does to each pod.
  Status Apply(ImageDepth16* depth, const ImageGray8& mask);

  const DepthFilterOptions& options() const { return options_; }

 private:
  struct Scratch;
  DepthFilter() = default;
  // One image whose mask was checked.
  void FilterOne(ImageDepth16* depth, const ImageGray8& mask, Scratch* s) const;
  DepthFilterOptions options_;
  std::unique_ptr<WorkerPool> pool_;
  std::vector<std::unique_ptr<Scratch>> scratch_;  // one per pool thread
};

}  // namespace holo
