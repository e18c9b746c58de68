// Non-rigid tracking of a model surface into a new multi-pod RGB-D frame:
// solves for the parameters of an embedded-deformation graph
// (deformation_graph.h) that warp the model's surface points onto the
// observed depth of every pod.
//
// Energy (each term has a weight and a switch):
//   data     point-to-plane distance n'ᵀ(v' − q) of each warped model point v'
//            (warped model normal n') to the depth point q of every pod that
//            sees it, by projective association (v' is projected into the pod,
//            q is the masked depth at that pixel); Huber-robust
//   hull     visual hull: a warped point must project inside every pod's
//            silhouette; residual = distance transform of the silhouette's
//            outside at the projection, in metres at the point's depth
//   rotation each A_k close to a rotation (Sumner: column orthonormality)
//   regularization  neighbouring nodes predict each other's positions:
//            A_j (g_k − g_j) + g_j + t_j − (g_k + t_k)
//   sparse   optional colour-feature correspondences (feature_matcher.h):
//            a point of the previous frame's observed surface, warped like a
//            model point, must land on its match in this frame
//            (point-to-point, Huber-robust)
//
// Solve: a rigid point-to-plane ICP for the global (R, T) first (coarse),
// then outer iterations of (re-associate, one Gauss–Newton step over all node
// parameters). Two interchangeable linear solvers with the same residuals:
// a hand-written block-sparse Gauss–Newton with preconditioned conjugate
// gradients (12×12 blocks, block-Jacobi), and Ceres (Levenberg–Marquardt,
// sparse normal Cholesky). docs/temporal.md compares them.
//
// After the solve every node is judged (NodeReport): mean data residual of
// the points it carries, the fraction of its observed points that violate
// the observation (seen through: the depth there is behind the point; or
// outside a silhouette), the stretch of its graph edges (topology change:
// neighbouring nodes no longer agree) and the singular values of A_k (a torn
// or folded surface). Failed nodes mark the regions the temporal fusion
// resets.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"
#include "server/temporal/deformation_graph.h"
#include "server/temporal/feature_matcher.h"

namespace holo {

enum class TrackerSolver {
  kGaussNewtonPcg,  // hand-written block-sparse GN + PCG (Eigen, 12×12 blocks)
  kCeres,           // Ceres Levenberg–Marquardt, SPARSE_NORMAL_CHOLESKY
};
// "gn" | "ceres".
StatusOr<TrackerSolver> ParseTrackerSolver(const std::string& name);
const char* TrackerSolverName(TrackerSolver s);

struct TrackerOptions {
  // Energy terms: on/off and weight (multiplies the squared residual).
  bool use_data = true;
  float data_weight = 1.0f;
  bool use_hull = true;
  float hull_weight = 0.5f;
  bool use_rotation = true;
  float rotation_weight = 0.02f;
  bool use_regularization = true;
  float regularization_weight = 10.0f;
  // Sparse colour-feature correspondences (only when Track gets features):
  // 1 on, 0 off, -1 by resolution: on when the widest pod's depth image is
  // at least 640 pixels wide (S8-VGA on, S8-QVGA off). Measured
  // (docs/temporal.md): at VGA they lower flicker (ratio 0.617 → 0.532) and
  // Chamfer; at QVGA they help less (0.456 → 0.423) for ≈ +10 CPU-ms per
  // frame on the tight QVGA frame budget.
  int use_sparse = -1;
  float sparse_weight = 1.0f;
  float sparse_huber_m = 0.02f;
  // A pair whose warped point is farther than this from its target at the
  // current linearisation contributes nothing (mismatches on repeated
  // texture such as stripes).
  float sparse_reject_m = 0.06f;

  // Coarse stage: rigid ICP iterations for the global (R, T) (0 = none).
  int rigid_iterations = 3;
  // Non-rigid outer iterations (association + one GN/LM step each).
  int iterations = 3;
  // Projective association: a depth point farther than this from the warped
  // model point is not a correspondence (metres).
  float association_max_m = 0.04f;
  // The data term's observed point is the mean of the masked depth pixels in
  // a (2r+1)² window around the projection that lie within
  // association_max_m of the warped point (the sensor noise is per pixel, so
  // this averages it down without blurring across depth edges). r in
  // pixels; 0 = the single pixel; -1 = by resolution, floor(width / 640):
  // a window of about the same surface footprint (S8-VGA 3×3, S8-QVGA 1
  // pixel). Measured (docs/temporal.md): on S8-VGA r = 1 beats 0 and 2; on
  // S8-QVGA r = 1 lowers flicker but costs Chamfer and the dropped pod's
  // kept surface.
  int data_window_px = -1;
  // Huber threshold of the data term (metres) and of the hull term.
  float huber_m = 0.008f;
  float hull_huber_m = 0.02f;
  // Silhouette violations smaller than this (pixels) are ignored.
  float hull_margin_px = 1.5f;

  TrackerSolver solver = TrackerSolver::kGaussNewtonPcg;
  int pcg_max_iterations = 30;  // 15 saves CPU on S8-QVGA but costs Chamfer on S8-VGA (docs/temporal.md)
  double pcg_relative_tolerance = 1e-3;
  // Levenberg–Marquardt style damping added to the diagonal of JᵀJ (relative to it, plus
  // an absolute floor for nodes without data).
  double damping = 1e-4;
  // Ceres: LM iterations per outer iteration.
  int ceres_iterations = 2;

  // Node judgement (NodeReport::failed).
  float fail_residual_m = 0.025f;       // mean |data residual| of the node's associated points
  float fail_violation_fraction = 0.4f; // share of its observed points that violate the observation
  float fail_stretch_factor = 0.3f;     // an edge residual longer than this · node spacing
  float fail_affine_scale = 0.25f;      // a singular value of A_k outside [1 − this, 1 / (1 − this)]: torn surface
  float min_support = 2.0f;             // sum of skin weights of observed points needed to judge residuals

  // Run the PCG product and the per-node PCG vector work (updates,
  // block-Jacobi preconditioner) on the worker pool (two hand-offs per PCG
  // iteration; the result does not depend on it). On by default since the
  // vector work runs there too (docs/temporal.md, "Speed work, third pass").
  bool parallel_pcg = true;
  int threads = 2;  // 0 = hardware concurrency
  Status Check() const;
  // Whether the sparse term is on for `rig` (use_sparse, by resolution if -1).
  bool SparseOn(const Rig& rig) const;
};

struct NodeReport {
  float residual_m = 0;   // mean |point-to-plane| of its associated points (skin-weighted)
  float observed = 0;     // skin-weighted count of its points with a correspondence or a violation
  float violations = 0;   // skin-weighted count of violations
  float stretch_m = 0;    // largest regularisation residual of its edges
  float scale_min = 1, scale_max = 1;  // singular values of A_k
  bool failed = false;
};

struct TrackResult {
  int iterations = 0;
  size_t num_points = 0;
  size_t associated_points = 0;  // points with at least one correspondence (final state)
  double data_rms_m = 0;         // RMS point-to-plane residual over correspondences (final state)
  double energy_initial = 0, energy_final = 0;  // total energy at the first and the last linearisation
  std::vector<NodeReport> nodes;
  int failed_nodes = 0;
  // Why: nodes failing each test (a node may fail several).
  int failed_residual = 0, failed_violation = 0, failed_stretch = 0, failed_affine = 0;
  // Wall time, ms.
  double rigid_ms = 0, associate_ms = 0, solve_ms = 0, total_ms = 0;
  int pcg_iterations = 0;        // summed over the outer iterations (GN solver)
  size_t sparse_pairs = 0;        // feature pairs used by the sparse term
  double sparse_rms_m = 0;        // RMS distance of the warped pairs to their targets (final state)
  double last_step_m = 0;        // largest node move (|Δt| + ‖ΔA‖·spacing) of the last GN step (GN solver)
};

class NonrigidTracker {
 public:
  explicit NonrigidTracker(TrackerOptions options);  // HOLO_CHECKs options.Check()
  ~NonrigidTracker();
  NonrigidTracker(const NonrigidTracker&) = delete;
  NonrigidTracker& operator=(const NonrigidTracker&) = delete;

  const TrackerOptions& options() const { return options_; }
  TrackerOptions& mutable_options() { return options_; }

  // Warps `points` (model surface, rest pose, with unit `normals`) by
  // `graph` (built on the same model; its parameters are the initial guess
  // and hold the solution on return, global transform folded into the
  // nodes) onto the masked depth of `frames`. Errors (InvalidArgument): pod
  // count or image sizes differ from the rig, sizes of points and normals
  // differ. An empty graph or no points is OK (nothing to do).
  // `features` (optional): colour-feature pairs from the previous frame (the
  // model's frame) to this one, used by the sparse term if use_sparse.
  Status Track(const Rig& rig, const RgbdFrameSet& frames, const std::vector<Eigen::Vector3f>& points,
               const std::vector<Eigen::Vector3f>& normals, DeformationGraph* graph, TrackResult* result,
               const std::vector<FeatureCorrespondence>* features = nullptr);

  // After Track: the distance (pixels, row-major) from each pixel of pod
  // `pod` to its nearest silhouette pixel (0 inside), or null if that pod had
  // no usable silhouette in the last frame.
  const float* SilhouetteDistance(size_t pod, int* width, int* height) const;

  struct Impl;

 private:
  TrackerOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace holo
