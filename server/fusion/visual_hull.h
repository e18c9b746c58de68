// The visual hull: a reconstruction from the pods' silhouettes alone, for
// sites whose pods are colour cameras without depth (the first real-time
// telepresence systems carved a hull from several colour cameras).
//
// A point is inside the hull when every pod that sees it sees it inside its
// mask. The hull is written as a signed distance field into a TsdfVolume,
// so that the site's marching cubes, clean-up, stream mesh and texturing
// run on it unchanged:
//
//   d(x) = max over pods p that see x of  −s_p(π_p(x)) · z_p(x) / f_p
//
// where s_p is the mask's signed distance transform in pixels (positive
// inside the silhouette, negative outside; OpenCV's distanceTransform on the
// mask and on its complement), z_p the point's depth in pod p's camera and
// f_p its focal length: the image distance to the silhouette's edge scaled
// to metres at that depth (the distance to the pod's silhouette cone,
// measured across the viewing ray). Positive d = outside (free space), the
// TSDF convention; the volume holds clamp(d / truncation, −1, 1).
//
// Cost: the field is evaluated only in blocks (8³ voxels) near the surface.
// Block centres on the bounding box's block grid are tested first; a block
// whose centre is farther from the surface than its half diagonal plus the
// truncation (with a safety factor, since the cone distance is an estimate)
// is skipped. Points seen by fewer than `min_views` pods are unobserved
// (weight 0): a hull seen from one or two pods is unbounded along their rays.
//
// Written here (no library computes a hull as a distance field over sparse
// blocks), using OpenCV for the distance transforms.
#pragma once

#include <memory>
#include <vector>

#include <Eigen/Core>

#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"
#include "server/fusion/tsdf.h"

namespace holo {

struct VisualHullOptions {
  // The region carved, world metres (min and max corners). Points outside it
  // are outside the hull.
  Eigen::Vector3f box_min{-1.5f, -1.5f, -0.05f};
  Eigen::Vector3f box_max{1.5f, 1.5f, 2.3f};
  // A point is observed when at least this many pods see it (project into
  // their image); fewer: unobserved.
  int min_views = 3;
  // Worker threads (0 = hardware concurrency).
  int threads = 2;

  // OK, or InvalidArgument naming the field.
  Status Check() const;
};

// Counters of the last Build.
struct VisualHullStats {
  size_t blocks_tested = 0;   // block centres evaluated
  size_t blocks_filled = 0;   // blocks written (near the surface)
  double distance_ms = 0;     // distance transforms
  double fill_ms = 0;         // block tests and voxel field
};

class VisualHull {
 public:
  // `options` must pass Check() (HOLO_CHECK otherwise; use Create for
  // untrusted values).
  explicit VisualHull(VisualHullOptions options);
  static StatusOr<std::unique_ptr<VisualHull>> Create(VisualHullOptions options);
  ~VisualHull();
  VisualHull(const VisualHull&) = delete;
  VisualHull& operator=(const VisualHull&) = delete;

  const VisualHullOptions& options() const { return options_; }

  // Resets `volume` and writes the hull of `frames`' masks into it (its
  // voxel size and truncation decide the resolution). Every pod must have a
  // mask of its depth camera's size (255 = person); colours are not
  // written. InvalidArgument (naming the pod) when the frame set does not
  // match the rig or a mask is missing or of the wrong size.
  Status Build(const Rig& rig, const RgbdFrameSet& frames, TsdfVolume* volume);

  const VisualHullStats& stats() const { return stats_; }

 private:
  struct Impl;
  VisualHullOptions options_;
  std::unique_ptr<Impl> impl_;
  VisualHullStats stats_;
};

}  // namespace holo
