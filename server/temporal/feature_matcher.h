// Sparse colour-feature correspondences between consecutive frame sets, for
// the tracker's optional sparse term (nonrigid_tracker.h, use_sparse): ORB
// keypoints (OpenCV) are detected in every pod's colour image inside its
// (slightly eroded) mask, matched to the same pod's keypoints of the previous
// call (Hamming distance, Lowe ratio test and mutual best match), and both
// ends are lifted to world space with the pod's depth (median of the masked
// depth in a small window). A pair is kept if both ends have depth and the 3D
// displacement is at most `max_motion_m`.
//
// Only pods whose depth is registered to colour (PodCalibration::IsRegistered,
// as the studio rigs deliver) are used; other pods give no features. Pods
// without colour, depth or mask in a frame give none either.
//
// Not thread-safe; one instance per stream.
#pragma once

#include <memory>
#include <vector>

#include <Eigen/Core>

#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"

namespace holo {

struct FeatureMatchOptions {
  int max_features_per_pod = 400;  // ORB keypoints per pod image
  int max_hamming = 60;            // of a match (256-bit descriptors)
  float ratio = 0.8f;              // best / second-best Hamming distance must be below this
  float max_motion_m = 0.25f;      // 3D displacement of a pair between the two frames
  int depth_window_px = 2;         // depth of a keypoint: median of the (2r+1)² masked pixels
  int mask_erode_px = 3;           // keypoints this far inside the mask (no silhouette mixing)
  int threads = 2;                 // detection runs per pod on this many threads (0 = hardware concurrency)
  Status Check() const;
};

// One match: a point of the previous frame's observed surface and where it is
// now (world coordinates).
struct FeatureCorrespondence {
  Eigen::Vector3f from = Eigen::Vector3f::Zero();
  Eigen::Vector3f to = Eigen::Vector3f::Zero();
  int pod = 0;
};

class FeatureMatcher {
 public:
  explicit FeatureMatcher(FeatureMatchOptions options);  // HOLO_CHECKs options.Check()
  ~FeatureMatcher();
  FeatureMatcher(const FeatureMatcher&) = delete;
  FeatureMatcher& operator=(const FeatureMatcher&) = delete;

  // Detects this frame set's features, matches them to the previous call's
  // and writes the pairs to `out` (empty on the first call or after Reset).
  // Errors (InvalidArgument, state unchanged): pod count differs from the rig.
  Status Match(const Rig& rig, const RgbdFrameSet& frames, std::vector<FeatureCorrespondence>* out);

  // Forgets the previous frame.
  void Reset();

  // Keypoints with depth found in the last call, summed over pods.
  size_t last_keypoints() const { return last_keypoints_; }

  struct Impl;

 private:
  FeatureMatchOptions options_;
  std::unique_ptr<Impl> impl_;
  size_t last_keypoints_ = 0;
};

}  // namespace holo
