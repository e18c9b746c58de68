// Novel-view evaluation of a textured mesh against the synthetic studio's
// ground truth: render the mesh from cameras no pod has, compare with the
// studio's noise-free render of the true scene inside the true foreground.
// Used by holoport-bench texture and fusion (metric novel_view_psnr_db).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/camera.h"
#include "common/image.h"
#include "common/mesh.h"
#include "common/status.h"
#include "studio/studio.h"

namespace holo {

struct NovelViewOptions {
  int num_views = 4;
  // Cameras on a horizontal circle of this radius (m) around `target`'s
  // vertical axis, at this height (m), looking at `target`.
  float radius_m = 2.0f;
  float height_m = 1.6f;
  Eigen::Vector3f target = Eigen::Vector3f(0.0f, 0.0f, 1.0f);
  // Azimuth of the first view (degrees, from +x towards +y); the others are
  // spaced 360/num_views apart. 22.5° falls halfway between studio-8's pods.
  float first_azimuth_deg = 22.5f;
  // Resolution and intrinsics of the views (e.g. a pod's colour intrinsics).
  Intrinsics intrinsics = Intrinsics::FromFov(320, 240, 70.0);
};

struct NovelView {
  CameraModel camera;
  float azimuth_deg = 0;
};

std::vector<NovelView> MakeNovelViews(const NovelViewOptions& options);

struct NovelViewScore {
  float azimuth_deg = 0;
  double psnr_db = 0;  // inside the ground-truth foreground mask
  double ssim = 0;     // luma SSIM, averaged inside the ground-truth foreground mask
  size_t mask_pixels = 0;
};

// Renders `textured` (per-vertex colours) from `view` with RenderMesh and the
// truth with studio.RenderView(frame, ...). Both images are set to black
// outside the true foreground mask (so SSIM windows at the silhouette compare
// like with like); PSNR and SSIM are taken inside that mask. If
// `png_prefix` is not empty, writes <prefix>.png: truth left, ours right.
// Errors: InvalidArgument (empty mask, bad mesh or camera), I/O errors.
StatusOr<NovelViewScore> ScoreNovelView(const SyntheticStudio& studio, int64_t frame, const Mesh& textured,
                                        const NovelView& view, const std::string& png_prefix = "");

}  // namespace holo
