#include "server/temporal/nonrigid_tracker.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <ceres/ceres.h>
#include <opencv2/imgproc.hpp>

#include "common/worker_pool.h"

namespace holo {

using Eigen::Matrix3d;
using Eigen::Matrix3f;
using Eigen::Vector3d;
using Eigen::Vector3f;
using Vec12 = Eigen::Matrix<double, 12, 1>;
using Mat12 = Eigen::Matrix<double, 12, 12>;

StatusOr<TrackerSolver> ParseTrackerSolver(const std::string& name) {
  if (name == "gn") return TrackerSolver::kGaussNewtonPcg;
  if (name == "ceres") return TrackerSolver::kCeres;
  return InvalidArgument("unknown tracker solver '" + name + "' (known: gn, ceres)");
}

const char* TrackerSolverName(TrackerSolver s) { return s == TrackerSolver::kCeres ? "ceres" : "gn"; }

Status TrackerOptions::Check() const {
  auto nonneg = [](float v, const char* name) -> Status {
    if (!(v >= 0) || !std::isfinite(v)) return InvalidArgument(std::string(name) + " must be >= 0, got " + std::to_string(v));
    return OkStatus();
  };
  HOLO_RETURN_IF_ERROR(nonneg(data_weight, "data_weight"));
  HOLO_RETURN_IF_ERROR(nonneg(hull_weight, "hull_weight"));
  HOLO_RETURN_IF_ERROR(nonneg(rotation_weight, "rotation_weight"));
  HOLO_RETURN_IF_ERROR(nonneg(regularization_weight, "regularization_weight"));
  HOLO_RETURN_IF_ERROR(nonneg(sparse_weight, "sparse_weight"));
  if (use_sparse < -1 || use_sparse > 1) return InvalidArgument("use_sparse must be -1, 0 or 1, got " + std::to_string(use_sparse));
  if (!(sparse_huber_m > 0)) return InvalidArgument("sparse_huber_m must be > 0");
  if (!(sparse_reject_m > 0)) return InvalidArgument("sparse_reject_m must be > 0");
  if (data_window_px < -1 || data_window_px > 16) return InvalidArgument("data_window_px must be in [-1, 16]");
  if (rigid_iterations < 0 || rigid_iterations > 100) return InvalidArgument("rigid_iterations must be in [0, 100]");
  if (iterations < 0 || iterations > 100) return InvalidArgument("iterations must be in [0, 100]");
  if (!(association_max_m > 0)) return InvalidArgument("association_max_m must be > 0");
  if (!(huber_m > 0) || !(hull_huber_m > 0)) return InvalidArgument("huber_m and hull_huber_m must be > 0");
  HOLO_RETURN_IF_ERROR(nonneg(hull_margin_px, "hull_margin_px"));
  if (pcg_max_iterations < 1 || pcg_max_iterations > 10000) return InvalidArgument("pcg_max_iterations must be in [1, 10000]");
  if (!(damping >= 0)) return InvalidArgument("damping must be >= 0");
  if (!(fail_affine_scale >= 0 && fail_affine_scale < 1)) return InvalidArgument("fail_affine_scale must be in [0, 1)");
  if (ceres_iterations < 1 || ceres_iterations > 100) return InvalidArgument("ceres_iterations must be in [1, 100]");
  if (threads < 0 || threads > 256) return InvalidArgument("threads must be in [0, 256]");
  return OkStatus();
}

bool TrackerOptions::SparseOn(const Rig& rig) const {
  if (use_sparse >= 0) return use_sparse == 1;
  int width = 0;
  for (const PodCalibration& p : rig.pods) width = std::max(width, p.depth.width);
  return width >= 640;
}

namespace {

double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// One pod of the current frame, prepared for association.
struct PodFrame {
  bool usable = false;          // has usable depth
  bool has_silhouette = false;  // mask with some foreground: the hull applies
  bool distorted = false;
  int width = 0, height = 0;
  int window = 0;  // half-size of the data term's depth window (pixels)
  float fx = 0, fy = 0, cx = 0, cy = 0;
  Matrix3f r_cw;  // camera_from_world
  Vector3f t_cw;
  Matrix3f r_wc;
  Vector3f center;
  CameraModel camera;
  std::vector<float> depth;  // metres, 0 = none (invalid or outside the mask)
  cv::Mat outside;           // CV_8U: 255 outside the silhouette
  cv::Mat dt;                // CV_32F: pixels to the nearest foreground pixel (0 inside)

  // Pixel of a camera-space point; false if behind or outside the image.
  bool Project(const Vector3f& pc, float* u, float* v) const {
    if (pc.z() <= 0.05f) return false;
    if (!distorted) {
      *u = fx * pc.x() / pc.z() + cx;
      *v = fy * pc.y() / pc.z() + cy;
    } else {
      Eigen::Vector2f px;
      if (!camera.ProjectCamera(pc, &px)) return false;
      *u = px.x();
      *v = px.y();
    }
    return *u > -0.5f && *v > -0.5f && *u < width - 0.5f && *v < height - 0.5f;
  }
};

// Linearised point terms of one model point: Σ ρ_j (r_j + g_jᵀ Δv')² =
// Δᵀ G Δ + 2 eᵀ Δ + c, Δ = change of the warped position.
struct PointLin {
  Matrix3d g = Matrix3d::Zero();
  Vector3d e = Vector3d::Zero();
  double energy = 0;
  // Judgement: correspondences, |residual| sum, violations.
  int correspondences = 0;
  float abs_residual_sum = 0;
  bool violated = false;
};

inline void HuberWeight(double r, double delta, double* rho_w, double* energy) {
  const double a = std::abs(r);
  if (a <= delta) {
    *rho_w = 1.0;
    *energy = r * r;
  } else {
    *rho_w = delta / a;
    *energy = 2 * delta * a - delta * delta;
  }
}

// Ceres cost of one model point: its linearised point terms as ≤ 3
// residuals sqrt(λ_i) u_iᵀ Δ + u_iᵀ e / sqrt(λ_i) (G = Σ λ_i u_i u_iᵀ).
class PointCost final : public ceres::CostFunction {
 public:
  PointCost(const DeformationGraph& graph, const SkinWeights& skin, const Vector3f& v, const Vector3d& p0,
            const Matrix3d& g, const Vector3d& e)
      : p0_(p0) {
    Eigen::SelfAdjointEigenSolver<Matrix3d> es(g);
    for (int i = 0; i < 3; ++i) {
      const double lambda = es.eigenvalues()[i];
      if (lambda > 1e-12) {
        rows_.row(i) = std::sqrt(lambda) * es.eigenvectors().col(i).transpose();
        offset_[i] = es.eigenvectors().col(i).dot(e) / std::sqrt(lambda);
      } else {
        rows_.row(i).setZero();
        offset_[i] = 0;
      }
    }
    set_num_residuals(3);
    for (int i = 0; i < kSkinNodes && skin.node[static_cast<size_t>(i)] >= 0; ++i) {
      const int k = skin.node[static_cast<size_t>(i)];
      w_[n_] = skin.weight[static_cast<size_t>(i)];
      h_[n_] = (v - graph.position(k)).cast<double>();
      g_[n_] = graph.position(k).cast<double>();
      ++n_;
      mutable_parameter_block_sizes()->push_back(12);
    }
  }
  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    Vector3d p = Vector3d::Zero();
    for (int i = 0; i < n_; ++i) {
      const double* x = params[i];
      Vector3d q;
      for (int a = 0; a < 3; ++a)
        q[a] = x[4 * a] * h_[i][0] + x[4 * a + 1] * h_[i][1] + x[4 * a + 2] * h_[i][2] + x[4 * a + 3];
      p += w_[i] * (q + g_[i]);
    }
    const Vector3d r = rows_ * (p - p0_) + offset_;
    for (int j = 0; j < 3; ++j) residuals[j] = r[j];
    if (jacobians) {
      for (int i = 0; i < n_; ++i) {
        if (!jacobians[i]) continue;
        double* jac = jacobians[i];  // 3 × 12, row-major
        for (int j = 0; j < 3; ++j)
          for (int a = 0; a < 3; ++a) {
            const double c = rows_(j, a) * w_[i];
            jac[12 * j + 4 * a + 0] = c * h_[i][0];
            jac[12 * j + 4 * a + 1] = c * h_[i][1];
            jac[12 * j + 4 * a + 2] = c * h_[i][2];
            jac[12 * j + 4 * a + 3] = c;
          }
      }
    }
    return true;
  }

 private:
  Vector3d p0_;
  Matrix3d rows_;
  Vector3d offset_;
  int n_ = 0;
  double w_[kSkinNodes];
  Vector3d h_[kSkinNodes];
  Vector3d g_[kSkinNodes];
};

class RotationCost final : public ceres::SizedCostFunction<6, 12> {
 public:
  explicit RotationCost(double sqrt_w) : s_(sqrt_w) {}
  bool Evaluate(double const* const* params, double* r, double** jac) const override {
    const double* x = params[0];
    Vector3d c[3];
    for (int j = 0; j < 3; ++j) c[j] = Vector3d(x[j], x[4 + j], x[8 + j]);
    const int pi[6] = {0, 0, 1, 0, 1, 2}, pj[6] = {1, 2, 2, 0, 1, 2};
    for (int m = 0; m < 6; ++m) r[m] = s_ * (c[pi[m]].dot(c[pj[m]]) - (m >= 3 ? 1.0 : 0.0));
    if (jac && jac[0]) {
      double* J = jac[0];
      std::fill(J, J + 72, 0.0);
      for (int m = 0; m < 6; ++m)
        for (int a = 0; a < 3; ++a) {
          J[12 * m + 4 * a + pi[m]] += s_ * c[pj[m]][a];
          J[12 * m + 4 * a + pj[m]] += s_ * c[pi[m]][a];
        }
    }
    return true;
  }

 private:
  double s_;
};

class RegularizationCost final : public ceres::SizedCostFunction<3, 12, 12> {
 public:
  RegularizationCost(const Vector3d& gj, const Vector3d& gk, double sqrt_w) : gj_(gj), gk_(gk), s_(sqrt_w) {}
  bool Evaluate(double const* const* params, double* r, double** jac) const override {
    const double* xj = params[0];
    const double* xk = params[1];
    const Vector3d d = gk_ - gj_;
    for (int a = 0; a < 3; ++a)
      r[a] = s_ * (xj[4 * a] * d[0] + xj[4 * a + 1] * d[1] + xj[4 * a + 2] * d[2] + xj[4 * a + 3] + gj_[a] - gk_[a] -
                   xk[4 * a + 3]);
    if (jac) {
      if (jac[0]) {
        std::fill(jac[0], jac[0] + 36, 0.0);
        for (int a = 0; a < 3; ++a) {
          for (int b = 0; b < 3; ++b) jac[0][12 * a + 4 * a + b] = s_ * d[b];
          jac[0][12 * a + 4 * a + 3] = s_;
        }
      }
      if (jac[1]) {
        std::fill(jac[1], jac[1] + 36, 0.0);
        for (int a = 0; a < 3; ++a) jac[1][12 * a + 4 * a + 3] = -s_;
      }
    }
    return true;
  }

 private:
  Vector3d gj_, gk_;
  double s_;
};

Vec12 NodeParams(const DeformationGraph& g, int k) {
  Vec12 x;
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) x[4 * a + b] = g.affine(k)(a, b);
    x[4 * a + 3] = g.translation(k)[a];
  }
  return x;
}

void SetNodeParams(DeformationGraph* g, int k, const double* x) {
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) g->affine(k)(a, b) = static_cast<float>(x[4 * a + b]);
    g->translation(k)[a] = static_cast<float>(x[4 * a + 3]);
  }
}

}  // namespace

struct NonrigidTracker::Impl {
  explicit Impl(int threads) : pool(threads) {}
  WorkerPool pool;
  std::vector<PodFrame> pods;
  // Model points come first; points from n_model on are sparse feature
  // points with targets sparse_to[i − n_model].
  size_t n_model = 0;
  std::vector<Vector3f> all_points, all_normals, sparse_to;
  std::vector<SkinWeights> skins;
  std::vector<Vector3f> warped, warped_normals;
  std::vector<PointLin> lin;
  // Parallel GN: tasks own contiguous node rows [row_begin[t], row_begin[t + 1])
  // and write only those rows; task_points[t] / task_edges[t] list the points /
  // regularisation edges (k, l) touching a node of task t.
  std::vector<size_t> row_begin;
  std::vector<std::vector<int32_t>> task_points;
  std::vector<std::vector<int32_t>> task_active;  // task_points with data or hull terms (this iteration)
  std::vector<std::vector<std::pair<int32_t, int32_t>>> task_edges;
  std::vector<std::array<Eigen::Vector4d, kSkinNodes>> hh;  // (v − g_a, 1) per point and skin node
  std::vector<Mat12, Eigen::aligned_allocator<Mat12>> rot;  // rotation-term JᵀJ per node
  std::vector<Vec12> damp;                                  // damping added to the diagonal
  std::vector<Vec12> rhs, x, r, z, p, q;
  std::vector<Eigen::Matrix<double, 12, 12>, Eigen::aligned_allocator<Mat12>> precond;

  Status Prepare(const Rig& rig, const RgbdFrameSet& frames, int data_window_px);
  void WarpPoints(const DeformationGraph& graph, const std::vector<Vector3f>& points,
                  const std::vector<Vector3f>& normals);
  void Associate(const TrackerOptions& o, size_t n);
  void AssociatePoint(const TrackerOptions& o, size_t i, PointLin* out) const;
};

Status NonrigidTracker::Impl::Prepare(const Rig& rig, const RgbdFrameSet& frames, int data_window_px) {
  if (frames.frames.size() != rig.pods.size())
    return InvalidArgument("frame set has " + std::to_string(frames.frames.size()) + " pods but the rig has " +
                           std::to_string(rig.pods.size()));
  // Validate every pod first (state unchanged on error), then prepare the
  // pods in parallel (depth conversion and the silhouette distance transform).
  for (size_t i = 0; i < rig.pods.size(); ++i) {
    const PodCalibration& cal = rig.pods[i];
    const RgbdFrame& f = frames.frames[i];
    const int w = cal.depth.width, h = cal.depth.height;
    if (f.depth.empty()) continue;  // no data from this pod
    if (f.depth.width() != w || f.depth.height() != h)
      return InvalidArgument("pod " + std::to_string(i) + " (" + cal.name + "): depth image is " +
                             std::to_string(f.depth.width()) + "x" + std::to_string(f.depth.height()) +
                             " but the rig says " + std::to_string(w) + "x" + std::to_string(h));
    if (!f.mask.empty() && (f.mask.width() != w || f.mask.height() != h))
      return InvalidArgument("pod " + std::to_string(i) + " (" + cal.name + "): mask size differs from the depth image");
  }
  pods.resize(rig.pods.size());
  pool.ParallelFor(static_cast<int>(rig.pods.size()), [&](int pi) {
    const size_t i = static_cast<size_t>(pi);
    const PodCalibration& cal = rig.pods[i];
    const RgbdFrame& f = frames.frames[i];
    PodFrame& pod = pods[i];
    pod.usable = false;
    pod.has_silhouette = false;
    const int w = cal.depth.width, h = cal.depth.height;
    if (f.depth.empty()) return;
    const bool has_mask = !f.mask.empty();
    pod.width = w;
    pod.height = h;
    pod.fx = static_cast<float>(cal.depth.fx);
    pod.fy = static_cast<float>(cal.depth.fy);
    pod.cx = static_cast<float>(cal.depth.cx);
    pod.cy = static_cast<float>(cal.depth.cy);
    pod.distorted = cal.depth.HasDistortion();
    pod.window = data_window_px >= 0 ? data_window_px : w / 640;
    pod.camera = cal.DepthCamera();
    pod.r_wc = cal.world_from_depth.linear();
    pod.center = cal.world_from_depth.translation();
    pod.r_cw = pod.r_wc.transpose();
    pod.t_cw = -pod.r_cw * pod.center;
    pod.depth.resize(static_cast<size_t>(w) * h);
    const uint16_t* d = f.depth.data();
    const uint8_t* m = has_mask ? f.mask.data() : nullptr;
    size_t valid = 0, fg = 0;
    for (size_t p = 0; p < pod.depth.size(); ++p) {
      const bool inside = m == nullptr || m[p] != 0;
      fg += inside;
      const float z = inside ? d[p] * 0.001f : 0.0f;
      pod.depth[p] = z;
      valid += z > 0;
    }
    pod.usable = valid > 0;
    if (has_mask && fg > 0 && pod.usable) {
      pod.has_silhouette = true;
      pod.outside.create(h, w, CV_8U);
      for (int y = 0; y < h; ++y) {
        uint8_t* row = pod.outside.ptr<uint8_t>(y);
        for (int x = 0; x < w; ++x) row[x] = m[static_cast<size_t>(y) * w + x] != 0 ? 0 : 255;
      }
      cv::distanceTransform(pod.outside, pod.dt, cv::DIST_L2, 3);
    }
  });
  return OkStatus();
}

void NonrigidTracker::Impl::WarpPoints(const DeformationGraph& graph, const std::vector<Vector3f>& points,
                                       const std::vector<Vector3f>& normals) {
  const int n = static_cast<int>(points.size());
  const int chunks = (n + 511) / 512;
  pool.ParallelFor(chunks, [&](int c) {
    const size_t a = static_cast<size_t>(c) * 512, b = std::min(points.size(), a + 512);
    for (size_t i = a; i < b; ++i) {
      if (!skins[i].valid()) {
        warped[i] = graph.global() * points[i];
        warped_normals[i] = graph.global().linear() * normals[i];
        continue;
      }
      warped[i] = graph.Warp(points[i], skins[i]);
      warped_normals[i] = graph.WarpNormal(normals[i], skins[i]);
    }
  });
}

void NonrigidTracker::Impl::AssociatePoint(const TrackerOptions& o, size_t i, PointLin* out) const {
  *out = PointLin();
  const Vector3f& pw = warped[i];
  if (i >= n_model) {
    // Sparse colour correspondence: point-to-point, Huber on the distance.
    const Vector3d r = (pw - sparse_to[i - n_model]).cast<double>();
    if (r.norm() > o.sparse_reject_m) return;  // a wrong match (repeated texture): no term
    double rho, en;
    HuberWeight(r.norm(), o.sparse_huber_m, &rho, &en);
    out->g = o.sparse_weight * rho * Matrix3d::Identity();
    out->e = o.sparse_weight * rho * r;
    out->energy = o.sparse_weight * en;
    return;
  }
  const Vector3f& nw = warped_normals[i];
  const double sd = o.data_weight, sh = o.hull_weight;
  for (const PodFrame& pod : pods) {
    if (!pod.usable) continue;
    const Vector3f pc = pod.r_cw * pw + pod.t_cw;
    float u, v;
    if (!pod.Project(pc, &u, &v)) continue;
    const int ui = static_cast<int>(std::lround(u)), vi = static_cast<int>(std::lround(v));
    const size_t pix = static_cast<size_t>(vi) * pod.width + ui;
    // Visual hull.
    if (pod.has_silhouette) {
      const float dt = pod.dt.at<float>(vi, ui);
      if (dt > o.hull_margin_px) {
        if (dt > 3.0f && dt * pc.z() / pod.fx > 0.02f) out->violated = true;
        if (o.use_hull && sh > 0) {
          const float scale = pc.z() / pod.fx;  // metres per pixel at the point
          const double r = (dt - o.hull_margin_px) * scale;
          // Image gradient of the distance transform (central differences).
          const int x0 = std::max(0, ui - 1), x1 = std::min(pod.width - 1, ui + 1);
          const int y0 = std::max(0, vi - 1), y1 = std::min(pod.height - 1, vi + 1);
          const float gu = (pod.dt.at<float>(vi, x1) - pod.dt.at<float>(vi, x0)) / std::max(1, x1 - x0);
          const float gv = (pod.dt.at<float>(y1, ui) - pod.dt.at<float>(y0, ui)) / std::max(1, y1 - y0);
          // d(u,v)/d(camera point), then to world.
          const float iz = 1.0f / pc.z();
          const Vector3f du(pod.fx * iz, 0, -pod.fx * pc.x() * iz * iz);
          const Vector3f dv(0, pod.fy * iz, -pod.fy * pc.y() * iz * iz);
          const Vector3f gc = scale * (gu * du + gv * dv);
          const Vector3d g = (pod.r_wc * gc).cast<double>();
          double rho, en;
          HuberWeight(r, o.hull_huber_m, &rho, &en);
          out->g += sh * rho * g * g.transpose();
          out->e += sh * rho * g * r;
          out->energy += sh * en;
        }
        continue;
      }
    }
    // Data: front-facing points only.
    const Vector3f to_cam = pod.center - pw;
    if (nw.dot(to_cam) <= 0.1f * to_cam.norm()) continue;
    const float z = pod.depth[pix];
    if (z <= 0) continue;
    if (z > pc.z() + o.association_max_m) {
      // The pod sees through the point, unless this is an edge pixel (flying
      // pixels, silhouettes): the whole 3×3 neighbourhood must be behind it.
      float zmin = z;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int x = std::clamp(ui + dx, 0, pod.width - 1), y = std::clamp(vi + dy, 0, pod.height - 1);
          const float zn = pod.depth[static_cast<size_t>(y) * pod.width + x];
          zmin = std::min(zmin, zn <= 0 ? 0.0f : zn);
        }
      if (zmin > pc.z() + o.association_max_m) out->violated = true;
      continue;
    }
    // The observed point: the mean of the window's depth pixels within the
    // association distance of the warped point (per-pixel sensor noise is
    // independent, so this averages it down; on a plane the mean of the
    // back-projected pixels lies on the plane).
    Vector3f qc((ui - pod.cx) * z / pod.fx, (vi - pod.cy) * z / pod.fy, z);
    if (pod.window > 0) {
      float su = 0, sv = 0, sz = 0;
      int cnt = 0;
      const int x0 = std::max(0, ui - pod.window), x1 = std::min(pod.width - 1, ui + pod.window);
      const int y0 = std::max(0, vi - pod.window), y1 = std::min(pod.height - 1, vi + pod.window);
      for (int y = y0; y <= y1; ++y) {
        const float* row = pod.depth.data() + static_cast<size_t>(y) * pod.width;
        for (int x = x0; x <= x1; ++x) {
          const float zn = row[x];
          if (zn <= 0 || std::abs(zn - pc.z()) > o.association_max_m) continue;
          su += static_cast<float>(x) * zn;
          sv += static_cast<float>(y) * zn;
          sz += zn;
          ++cnt;
        }
      }
      if (cnt > 1) {
        const float inv = 1.0f / static_cast<float>(cnt);
        qc = Vector3f((su * inv - pod.cx * sz * inv) / pod.fx, (sv * inv - pod.cy * sz * inv) / pod.fy, sz * inv);
      }
    }
    const Vector3f q = pod.r_wc * qc + pod.center;
    if ((q - pw).squaredNorm() > o.association_max_m * o.association_max_m) continue;
    const double r = nw.dot(pw - q);
    ++out->correspondences;
    out->abs_residual_sum += static_cast<float>(std::abs(r));
    if (o.use_data && sd > 0) {
      double rho, en;
      HuberWeight(r, o.huber_m, &rho, &en);
      const Vector3d g = nw.cast<double>();
      out->g += sd * rho * g * g.transpose();
      out->e += sd * rho * g * r;
      out->energy += sd * en;
    }
  }
}

void NonrigidTracker::Impl::Associate(const TrackerOptions& o, size_t n) {
  const int chunks = static_cast<int>((n + 255) / 256);
  pool.ParallelFor(chunks, [&](int c) {
    const size_t a = static_cast<size_t>(c) * 256, b = std::min(n, a + 256);
    for (size_t i = a; i < b; ++i) AssociatePoint(o, i, &lin[i]);
  });
}

NonrigidTracker::NonrigidTracker(TrackerOptions options) : options_(options) {
  HOLO_CHECK(options_.Check().ok());
  impl_ = std::make_unique<Impl>(options_.threads);
}

NonrigidTracker::~NonrigidTracker() = default;

const float* NonrigidTracker::SilhouetteDistance(size_t pod, int* width, int* height) const {
  if (pod >= impl_->pods.size() || !impl_->pods[pod].has_silhouette) return nullptr;
  const PodFrame& p = impl_->pods[pod];
  *width = p.width;
  *height = p.height;
  return p.dt.ptr<float>(0);
}

Status NonrigidTracker::Track(const Rig& rig, const RgbdFrameSet& frames, const std::vector<Vector3f>& model_points,
                              const std::vector<Vector3f>& model_normals, DeformationGraph* graph, TrackResult* result,
                              const std::vector<FeatureCorrespondence>* features) {
  const auto t_start = std::chrono::steady_clock::now();
  HOLO_RETURN_IF_ERROR(options_.Check());
  *result = TrackResult();
  if (model_points.size() != model_normals.size())
    return InvalidArgument("tracker: " + std::to_string(model_points.size()) + " points but " +
                           std::to_string(model_normals.size()) + " normals");
  Impl& m = *impl_;
  HOLO_RETURN_IF_ERROR(m.Prepare(rig, frames, options_.data_window_px));
  const size_t num_nodes = graph->num_nodes();
  result->num_points = model_points.size();
  result->nodes.assign(num_nodes, NodeReport());
  if (model_points.empty() || num_nodes == 0) return OkStatus();
  const TrackerOptions& o = options_;
  // Points of the solve: the model points, then (sparse term) the previous
  // frame's ends of the feature correspondences, warped like model points;
  // their targets are the current frame's ends.
  m.n_model = model_points.size();
  m.sparse_to.clear();
  const bool sparse = o.SparseOn(rig) && o.sparse_weight > 0 && features != nullptr && !features->empty();
  if (sparse) {
    m.all_points = model_points;
    m.all_normals = model_normals;
    for (const FeatureCorrespondence& c : *features) {
      if (!c.from.allFinite() || !c.to.allFinite()) continue;
      m.all_points.push_back(c.from);
      m.all_normals.push_back(Vector3f::Zero());
      m.sparse_to.push_back(c.to);
    }
    result->sparse_pairs = m.sparse_to.size();
  }
  const std::vector<Vector3f>& points = sparse ? m.all_points : model_points;
  const std::vector<Vector3f>& normals = sparse ? m.all_normals : model_normals;
  const size_t n = points.size();

  // Skinning (rest pose, fixed for this call).
  m.skins.resize(n);
  m.warped.resize(n);
  m.warped_normals.resize(n);
  m.lin.resize(n);
  m.pool.ParallelFor(static_cast<int>((n + 511) / 512), [&](int c) {
    const size_t a = static_cast<size_t>(c) * 512, b = std::min(n, a + 512);
    for (size_t i = a; i < b; ++i) m.skins[i] = graph->Skin(points[i]);
  });

  // ---- Coarse: rigid ICP on the global transform.
  auto t0 = std::chrono::steady_clock::now();
  for (int it = 0; it < o.rigid_iterations; ++it) {
    m.WarpPoints(*graph, points, normals);
    m.Associate(o, n);
    Eigen::Matrix<double, 6, 6> hr = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> br = Eigen::Matrix<double, 6, 1>::Zero();
    double energy = 0;
    for (size_t i = 0; i < n; ++i) {
      const PointLin& l = m.lin[i];
      energy += l.energy;
      if (l.g.isZero(0)) continue;
      const Vector3d p = m.warped[i].cast<double>();
      Matrix3d px;  // [p]×: Δv' = ω × p + τ = −[p]× ω + τ
      px << 0, -p.z(), p.y(), p.z(), 0, -p.x(), -p.y(), p.x(), 0;
      Eigen::Matrix<double, 3, 6> jv;
      jv << -px, Matrix3d::Identity();
      hr += jv.transpose() * l.g * jv;
      br -= jv.transpose() * l.e;
    }
    if (it == 0) result->energy_initial = energy;
    hr.diagonal() += 1e-6 * hr.diagonal() + Eigen::Matrix<double, 6, 1>::Constant(1e-9);
    const Eigen::Matrix<double, 6, 1> d = hr.ldlt().solve(br);
    if (!d.allFinite()) break;
    const Vector3d w = d.head<3>();
    Eigen::Isometry3f inc = Eigen::Isometry3f::Identity();
    if (w.norm() > 1e-12) inc.linear() = Eigen::AngleAxisd(w.norm(), w / w.norm()).toRotationMatrix().cast<float>();
    inc.translation() = d.tail<3>().cast<float>();
    graph->global() = inc * graph->global();
    if (d.norm() < 1e-6) break;
  }
  graph->FoldGlobalIntoNodes();
  result->rigid_ms = MsSince(t0);

  // ---- Fine: non-rigid GN / LM over all node parameters.
  const bool use_ceres = o.solver == TrackerSolver::kCeres;
  if (!use_ceres) {
    // Node ranges for the parallel assembly and the matrix-free product: a
    // few per thread (handed out dynamically), balanced by the points and
    // edges touching each node. A task writes only its own nodes' rows;
    // task_points / task_edges list the points / regularisation edges that
    // touch one of its nodes.
    std::vector<int32_t> load(num_nodes, 1);
    for (size_t i = 0; i < n; ++i)
      for (int a = 0; a < kSkinNodes && m.skins[i].node[static_cast<size_t>(a)] >= 0; ++a)
        load[static_cast<size_t>(m.skins[i].node[static_cast<size_t>(a)])] += 1;
    size_t total = 0;
    for (int32_t v : load) total += static_cast<size_t>(v);
    const size_t tasks = std::min(num_nodes, static_cast<size_t>(4 * m.pool.num_threads()));
    m.row_begin.assign(1, 0);
    size_t acc = 0;
    for (size_t k = 0; k < num_nodes; ++k) {
      acc += static_cast<size_t>(load[k]);
      if (m.row_begin.size() < tasks && acc * tasks >= total * m.row_begin.size()) m.row_begin.push_back(k + 1);
    }
    if (m.row_begin.back() != num_nodes) m.row_begin.push_back(num_nodes);
    const size_t num_tasks = m.row_begin.size() - 1;
    std::vector<int32_t> task_of(num_nodes);
    for (size_t t = 0; t < num_tasks; ++t)
      for (size_t k = m.row_begin[t]; k < m.row_begin[t + 1]; ++k) task_of[k] = static_cast<int32_t>(t);
    m.task_points.resize(num_tasks);
    m.task_active.resize(num_tasks);
    m.task_edges.resize(num_tasks);
    for (auto& v : m.task_points) v.clear();
    for (auto& v : m.task_edges) v.clear();
    for (size_t i = 0; i < n; ++i) {
      const SkinWeights& s = m.skins[i];
      std::array<int32_t, kSkinNodes> seen{};
      int ns = 0;
      for (int a = 0; a < kSkinNodes && s.node[static_cast<size_t>(a)] >= 0; ++a) {
        const int32_t t = task_of[static_cast<size_t>(s.node[static_cast<size_t>(a)])];
        if (std::find(seen.begin(), seen.begin() + ns, t) != seen.begin() + ns) continue;
        seen[static_cast<size_t>(ns++)] = t;
        m.task_points[static_cast<size_t>(t)].push_back(static_cast<int32_t>(i));
      }
    }
    for (size_t k = 0; k < num_nodes; ++k)
      for (int32_t l : graph->neighbors(static_cast<int>(k))) {
        const int32_t tk = task_of[k], tl = task_of[static_cast<size_t>(l)];
        m.task_edges[static_cast<size_t>(tk)].push_back({static_cast<int32_t>(k), l});
        if (tl != tk) m.task_edges[static_cast<size_t>(tl)].push_back({static_cast<int32_t>(k), l});
      }
  }

  std::vector<double> params;  // Ceres
  for (int it = 0; it < o.iterations; ++it) {
    t0 = std::chrono::steady_clock::now();
    m.WarpPoints(*graph, points, normals);
    m.Associate(o, n);
    result->associate_ms += MsSince(t0);
    t0 = std::chrono::steady_clock::now();
    double energy = 0;
    for (size_t i = 0; i < n; ++i) energy += m.lin[i].energy;
    const double wr = o.use_rotation ? o.rotation_weight : 0.0;
    const double wg = o.use_regularization ? o.regularization_weight : 0.0;
    // Rotation and regularisation energies.
    for (size_t k = 0; k < num_nodes; ++k) {
      const Matrix3f& a = graph->affine(static_cast<int>(k));
      if (wr > 0) {
        // Σ over the 6 residuals: the upper triangle of AᵀA − I.
        const Matrix3f e = a.transpose() * a - Matrix3f::Identity();
        energy += wr * (e(0, 1) * e(0, 1) + e(0, 2) * e(0, 2) + e(1, 2) * e(1, 2) + e.diagonal().squaredNorm());
      }
      if (wg > 0)
        for (int32_t l : graph->neighbors(static_cast<int>(k))) {
          const Vector3f d = graph->position(l) - graph->position(static_cast<int>(k));
          energy += wg * (a * d + graph->position(static_cast<int>(k)) + graph->translation(static_cast<int>(k)) -
                          graph->position(l) - graph->translation(l)).squaredNorm();
        }
    }
    if (it == 0 && o.rigid_iterations == 0) result->energy_initial = energy;
    result->energy_final = energy;

    if (use_ceres) {
      params.resize(num_nodes * 12);
      for (size_t k = 0; k < num_nodes; ++k) {
        const Vec12 x = NodeParams(*graph, static_cast<int>(k));
        std::copy(x.data(), x.data() + 12, params.data() + 12 * k);
      }
      ceres::Problem problem;
      for (size_t k = 0; k < num_nodes; ++k) problem.AddParameterBlock(params.data() + 12 * k, 12);
      std::vector<double*> blocks;
      for (size_t i = 0; i < n; ++i) {
        const PointLin& l = m.lin[i];
        if (l.g.isZero(0) || !m.skins[i].valid()) continue;
        blocks.clear();
        for (int a = 0; a < kSkinNodes && m.skins[i].node[static_cast<size_t>(a)] >= 0; ++a)
          blocks.push_back(params.data() + 12 * static_cast<size_t>(m.skins[i].node[static_cast<size_t>(a)]));
        problem.AddResidualBlock(new PointCost(*graph, m.skins[i], points[i], m.warped[i].cast<double>(), l.g, l.e),
                                 nullptr, blocks);
      }
      for (size_t k = 0; k < num_nodes; ++k) {
        if (wr > 0) problem.AddResidualBlock(new RotationCost(std::sqrt(wr)), nullptr, params.data() + 12 * k);
        if (wg > 0)
          for (int32_t l : graph->neighbors(static_cast<int>(k)))
            problem.AddResidualBlock(new RegularizationCost(graph->position(static_cast<int>(k)).cast<double>(),
                                                            graph->position(l).cast<double>(), std::sqrt(wg)),
                                     nullptr, params.data() + 12 * k, params.data() + 12 * static_cast<size_t>(l));
      }
      ceres::Solver::Options so;
      so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
      so.minimizer_type = ceres::TRUST_REGION;
      so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
      so.max_num_iterations = o.ceres_iterations;
      so.num_threads = o.threads > 0 ? o.threads : 2;
      so.logging_type = ceres::SILENT;
      so.minimizer_progress_to_stdout = false;
      ceres::Solver::Summary summary;
      ceres::Solve(so, &problem, &summary);
      for (size_t k = 0; k < num_nodes; ++k) SetNodeParams(graph, static_cast<int>(k), params.data() + 12 * k);
      result->solve_ms += MsSince(t0);
      ++result->iterations;
      continue;
    }

    // Hand-written GN. JᵀJ is never formed off the diagonal: the PCG
    // product JᵀJ p is evaluated matrix-free from the per-point 3×3 G (a
    // point's 4 nodes → Δv' = Σ w_a ΔA_a h_a + Δt_a, then G Δv', scattered
    // back), the regularisation edges and the per-node rotation blocks —
    // ~10× fewer flops than multiplying the 12×12 blocks of every node pair.
    // Only the diagonal blocks are assembled (for the block-Jacobi
    // preconditioner and the damping). Tasks own node ranges and write only
    // their own rows, so the sums do not depend on the thread count.
    m.rhs.resize(num_nodes);
    m.precond.resize(num_nodes);
    m.rot.resize(num_nodes);
    m.damp.resize(num_nodes);
    const size_t num_tasks = m.row_begin.size() - 1;
    // h_a = (v − g_a, 1) of each point and node.
    m.hh.resize(n);
    m.pool.ParallelFor(static_cast<int>((n + 511) / 512), [&](int c) {
      const size_t i0 = static_cast<size_t>(c) * 512, i1 = std::min(n, i0 + 512);
      for (size_t i = i0; i < i1; ++i) {
        const SkinWeights& s = m.skins[i];
        for (int a = 0; a < kSkinNodes; ++a) {
          if (s.node[static_cast<size_t>(a)] < 0) {
            m.hh[i][static_cast<size_t>(a)].setZero();
            continue;
          }
          const Vector3f hv = points[i] - graph->position(s.node[static_cast<size_t>(a)]);
          m.hh[i][static_cast<size_t>(a)] = Eigen::Vector4d(hv.x(), hv.y(), hv.z(), 1.0);
        }
      }
    });
    auto point_active = [&](size_t i) { return !m.lin[i].g.isZero(0) && m.skins[i].valid(); };
    m.pool.ParallelFor(static_cast<int>(num_tasks), [&](int task) {
      const size_t r0 = m.row_begin[static_cast<size_t>(task)], r1 = m.row_begin[static_cast<size_t>(task) + 1];
      auto mine = [r0, r1](int32_t k) { return static_cast<size_t>(k) >= r0 && static_cast<size_t>(k) < r1; };
      for (size_t k = r0; k < r1; ++k) {
        m.precond[k].setZero();  // holds the diagonal block D_k until inverted
        m.rot[k].setZero();
        m.rhs[k].setZero();
      }
      std::vector<int32_t>& active = m.task_active[static_cast<size_t>(task)];
      active.clear();
      for (int32_t ii : m.task_points[static_cast<size_t>(task)]) {
        const size_t i = static_cast<size_t>(ii);
        if (!point_active(i)) continue;
        active.push_back(ii);
        const PointLin& l = m.lin[i];
        const SkinWeights& s = m.skins[i];
        for (int a = 0; a < kSkinNodes && s.node[static_cast<size_t>(a)] >= 0; ++a) {
          const int32_t na = s.node[static_cast<size_t>(a)];
          if (!mine(na)) continue;
          const Eigen::Vector4d& h = m.hh[i][static_cast<size_t>(a)];
          const double w = s.weight[static_cast<size_t>(a)];
          const Eigen::Matrix4d mm = (w * w) * (h * h.transpose());
          Mat12& D = m.precond[static_cast<size_t>(na)];
          for (int p = 0; p < 3; ++p)
            for (int q = 0; q < 3; ++q) D.block<4, 4>(4 * p, 4 * q) += l.g(p, q) * mm;
          Vec12& bk = m.rhs[static_cast<size_t>(na)];
          for (int p = 0; p < 3; ++p) bk.segment<4>(4 * p) -= (w * l.e[p]) * h;
        }
      }
      if (wr > 0)
        for (size_t k = r0; k < r1; ++k) {
          const Vec12 x = NodeParams(*graph, static_cast<int>(k));
          Vector3d c[3];
          for (int j = 0; j < 3; ++j) c[j] = Vector3d(x[j], x[4 + j], x[8 + j]);
          const int pi[6] = {0, 0, 1, 0, 1, 2}, pj[6] = {1, 2, 2, 0, 1, 2};
          for (int mm = 0; mm < 6; ++mm) {
            Vec12 J = Vec12::Zero();
            for (int a = 0; a < 3; ++a) {
              J[4 * a + pi[mm]] += c[pj[mm]][a];
              J[4 * a + pj[mm]] += c[pi[mm]][a];
            }
            const double r = c[pi[mm]].dot(c[pj[mm]]) - (mm >= 3 ? 1.0 : 0.0);
            m.rot[k].noalias() += wr * J * J.transpose();
            m.rhs[k] -= wr * r * J;
          }
          m.precond[k] += m.rot[k];
        }
      if (wg > 0)
        for (const auto& [ki, l] : m.task_edges[static_cast<size_t>(task)]) {
          const Vector3f df = graph->position(l) - graph->position(ki);
          const Eigen::Vector4d hh(df.x(), df.y(), df.z(), 1.0);
          const Vector3d r = (graph->affine(ki) * df + graph->position(ki) + graph->translation(ki) -
                              graph->position(l) - graph->translation(l)).cast<double>();
          for (int a = 0; a < 3; ++a) {
            if (mine(ki)) {
              m.precond[static_cast<size_t>(ki)].block<4, 4>(4 * a, 4 * a) += wg * hh * hh.transpose();
              m.rhs[static_cast<size_t>(ki)].segment<4>(4 * a) -= wg * r[a] * hh;
            }
            if (mine(l)) {
              m.precond[static_cast<size_t>(l)](4 * a + 3, 4 * a + 3) += wg;
              m.rhs[static_cast<size_t>(l)][4 * a + 3] += wg * r[a];
            }
          }
        }
      // Damping (kept as a diagonal for the product) and the block-Jacobi preconditioner.
      for (size_t k = r0; k < r1; ++k) {
        Mat12& D = m.precond[k];
        for (int i = 0; i < 12; ++i) {
          m.damp[k][i] = o.damping * D(i, i) + 1e-6;
          D(i, i) += m.damp[k][i];
        }
        D = D.ldlt().solve(Mat12::Identity()).eval();
      }
    });
    // q = (JᵀJ + damping) p for the nodes of each task.
    auto product = [&](const std::vector<Vec12>& pv, std::vector<Vec12>* qv) {
      auto run = [&](auto&& fn) {
        if (o.parallel_pcg) {
          m.pool.ParallelFor(static_cast<int>(num_tasks), fn);
        } else {
          for (size_t t = 0; t < num_tasks; ++t) fn(static_cast<int>(t));
        }
      };
      run([&](int task) {
        const size_t r0 = m.row_begin[static_cast<size_t>(task)], r1 = m.row_begin[static_cast<size_t>(task) + 1];
        auto mine = [r0, r1](int32_t k) { return static_cast<size_t>(k) >= r0 && static_cast<size_t>(k) < r1; };
        for (size_t k = r0; k < r1; ++k) {
          (*qv)[k].noalias() = m.rot[k] * pv[k];
          (*qv)[k] += m.damp[k].cwiseProduct(pv[k]);
        }
        for (int32_t ii : m.task_active[static_cast<size_t>(task)]) {
          const size_t i = static_cast<size_t>(ii);
          const SkinWeights& s = m.skins[i];
          Vector3d dv = Vector3d::Zero();
          int cnt = 0;
          for (; cnt < kSkinNodes && s.node[static_cast<size_t>(cnt)] >= 0; ++cnt) {
            const Vec12& x = pv[static_cast<size_t>(s.node[static_cast<size_t>(cnt)])];
            const Eigen::Vector4d& h = m.hh[i][static_cast<size_t>(cnt)];
            const double w = s.weight[static_cast<size_t>(cnt)];
            dv += w * Vector3d(x.segment<4>(0).dot(h), x.segment<4>(4).dot(h), x.segment<4>(8).dot(h));
          }
          const Vector3d u = m.lin[i].g * dv;
          for (int a = 0; a < cnt; ++a) {
            const int32_t na = s.node[static_cast<size_t>(a)];
            if (!mine(na)) continue;
            const Eigen::Vector4d& h = m.hh[i][static_cast<size_t>(a)];
            const double w = s.weight[static_cast<size_t>(a)];
            Vec12& y = (*qv)[static_cast<size_t>(na)];
            for (int p = 0; p < 3; ++p) y.segment<4>(4 * p) += (w * u[p]) * h;
          }
        }
        if (wg > 0)
          for (const auto& [ki, l] : m.task_edges[static_cast<size_t>(task)]) {
            const Vector3f df = graph->position(l) - graph->position(ki);
            const Eigen::Vector4d hh(df.x(), df.y(), df.z(), 1.0);
            const Vec12& xk = pv[static_cast<size_t>(ki)];
            const Vec12& xl = pv[static_cast<size_t>(l)];
            for (int a = 0; a < 3; ++a) {
              const double jp = wg * (xk.segment<4>(4 * a).dot(hh) - xl[4 * a + 3]);
              if (mine(ki)) (*qv)[static_cast<size_t>(ki)].segment<4>(4 * a) += jp * hh;
              if (mine(l)) (*qv)[static_cast<size_t>(l)][4 * a + 3] -= jp;
            }
          }
      });
    };
    // PCG. Per-node vector work (updates, preconditioner) runs per task
    // with per-task partial dot products summed in task order, so the result
    // does not depend on the thread count.
    m.x.assign(num_nodes, Vec12::Zero());
    m.r = m.rhs;
    m.z.resize(num_nodes);
    m.q.resize(num_nodes);
    m.p.resize(num_nodes);
    std::vector<double> part_a(num_tasks), part_b(num_tasks);
    auto run_tasks = [&](auto&& fn) {
      if (o.parallel_pcg) {
        m.pool.ParallelFor(static_cast<int>(num_tasks), fn);
      } else {
        for (size_t t = 0; t < num_tasks; ++t) fn(static_cast<int>(t));
      }
    };
    auto sum = [&](const std::vector<double>& v) {
      double acc = 0;
      for (double x : v) acc += x;
      return acc;
    };
    run_tasks([&](int task) {
      double rz_t = 0, b_t = 0;
      for (size_t k = m.row_begin[static_cast<size_t>(task)]; k < m.row_begin[static_cast<size_t>(task) + 1]; ++k) {
        m.z[k].noalias() = m.precond[k].lazyProduct(m.r[k]);
        m.p[k] = m.z[k];
        rz_t += m.r[k].dot(m.z[k]);
        b_t += m.rhs[k].squaredNorm();
      }
      part_a[static_cast<size_t>(task)] = rz_t;
      part_b[static_cast<size_t>(task)] = b_t;
    });
    double rz = sum(part_a);
    const double b_norm = sum(part_b);
    const double tol2 = o.pcg_relative_tolerance * o.pcg_relative_tolerance * b_norm;
    for (int pit = 0; pit < o.pcg_max_iterations && b_norm > 0; ++pit) {
      product(m.p, &m.q);
      double pq = 0;
      for (size_t k = 0; k < num_nodes; ++k) pq += m.p[k].dot(m.q[k]);
      if (!(pq > 0)) break;
      const double alpha = rz / pq;
      run_tasks([&](int task) {
        double rr_t = 0, rz_t = 0;
        for (size_t k = m.row_begin[static_cast<size_t>(task)]; k < m.row_begin[static_cast<size_t>(task) + 1]; ++k) {
          m.x[k] += alpha * m.p[k];
          m.r[k] -= alpha * m.q[k];
          rr_t += m.r[k].squaredNorm();
          m.z[k].noalias() = m.precond[k].lazyProduct(m.r[k]);
          rz_t += m.r[k].dot(m.z[k]);
        }
        part_a[static_cast<size_t>(task)] = rr_t;
        part_b[static_cast<size_t>(task)] = rz_t;
      });
      const double rr = sum(part_a);
      ++result->pcg_iterations;
      if (rr < tol2) break;
      const double rz_new = sum(part_b);
      const double beta = rz_new / rz;
      rz = rz_new;
      for (size_t k = 0; k < num_nodes; ++k) m.p[k] = m.z[k] + beta * m.p[k];
    }
    bool finite = true;
    for (const Vec12& v : m.x) finite = finite && v.allFinite();
    double step = 0;  // largest node move of this step: |Δt| + ‖ΔA‖ · spacing
    if (finite) {
      const double spacing = graph->options().node_spacing_m;
      for (size_t k = 0; k < num_nodes; ++k) {
        const Vec12& dx = m.x[k];
        const double dt = Vector3d(dx[3], dx[7], dx[11]).norm();
        const double da = std::sqrt(dx.squaredNorm() - dt * dt);
        step = std::max(step, dt + da * spacing);
        const Vec12 x = NodeParams(*graph, static_cast<int>(k)) + dx;
        SetNodeParams(graph, static_cast<int>(k), x.data());
      }
    }
    result->solve_ms += MsSince(t0);
    ++result->iterations;
    result->last_step_m = step;
  }

  // ---- Judge the final state (model points only).
  t0 = std::chrono::steady_clock::now();
  m.WarpPoints(*graph, points, normals);
  m.Associate(o, n);
  result->associate_ms += MsSince(t0);
  if (sparse) {
    double s2 = 0;
    for (size_t i = m.n_model; i < n; ++i) s2 += (m.warped[i] - m.sparse_to[i - m.n_model]).squaredNorm();
    result->sparse_rms_m = std::sqrt(s2 / static_cast<double>(n - m.n_model));
  }
  double sq = 0;
  size_t cnt = 0;
  std::vector<float> wres(num_nodes, 0), wcorr(num_nodes, 0);
  for (size_t i = 0; i < m.n_model; ++i) {
    const PointLin& l = m.lin[i];
    const SkinWeights& s = m.skins[i];
    if (l.correspondences > 0) ++result->associated_points;
    const float mean_r = l.correspondences > 0 ? l.abs_residual_sum / l.correspondences : 0.0f;
    if (l.correspondences > 0) {
      sq += static_cast<double>(mean_r) * mean_r;
      ++cnt;
    }
    const bool observed = l.correspondences > 0 || l.violated;
    for (int a = 0; a < kSkinNodes && s.node[static_cast<size_t>(a)] >= 0; ++a) {
      const size_t k = static_cast<size_t>(s.node[static_cast<size_t>(a)]);
      const float w = s.weight[static_cast<size_t>(a)];
      if (observed) result->nodes[k].observed += w;
      if (l.violated) result->nodes[k].violations += w;
      if (l.correspondences > 0) {
        wres[k] += w * mean_r;
        wcorr[k] += w;
      }
    }
  }
  result->data_rms_m = cnt > 0 ? std::sqrt(sq / cnt) : 0.0;
  const float stretch_limit = o.fail_stretch_factor * graph->options().node_spacing_m;
  for (size_t k = 0; k < num_nodes; ++k) {
    NodeReport& nr = result->nodes[k];
    nr.residual_m = wcorr[k] > 0 ? wres[k] / wcorr[k] : 0.0f;
    const int ki = static_cast<int>(k);
    for (int32_t l : graph->neighbors(ki)) {
      const Vector3f d = graph->position(l) - graph->position(ki);
      const float s = (graph->affine(ki) * d + graph->position(ki) + graph->translation(ki) - graph->position(l) -
                       graph->translation(l)).norm();
      nr.stretch_m = std::max(nr.stretch_m, s);
      NodeReport& other = result->nodes[static_cast<size_t>(l)];
      other.stretch_m = std::max(other.stretch_m, s);
    }
  }
  for (size_t k = 0; k < num_nodes; ++k) {
    NodeReport& nr = result->nodes[k];
    bool failed = false;
    {
      const Eigen::JacobiSVD<Matrix3f> svd(graph->affine(static_cast<int>(k)));
      nr.scale_max = svd.singularValues()[0];
      nr.scale_min = svd.singularValues()[2];
      const float lo = 1.0f - o.fail_affine_scale;
      if (o.fail_affine_scale > 0 && (nr.scale_min < lo || nr.scale_max > 1.0f / lo)) {
        failed = true;
        ++result->failed_affine;
      }
    }
    if (nr.stretch_m > stretch_limit) {
      failed = true;
      ++result->failed_stretch;
    }
    if (nr.observed >= o.min_support) {
      if (nr.violations > o.fail_violation_fraction * nr.observed) {
        failed = true;
        ++result->failed_violation;
      }
      if (wcorr[k] >= o.min_support && nr.residual_m > o.fail_residual_m) {
        failed = true;
        ++result->failed_residual;
      }
    }
    const bool finite = graph->affine(static_cast<int>(k)).allFinite() && graph->translation(static_cast<int>(k)).allFinite();
    if (!finite) {
      failed = true;
      graph->affine(static_cast<int>(k)).setIdentity();
      graph->translation(static_cast<int>(k)).setZero();
    }
    nr.failed = failed;
    result->failed_nodes += failed;
  }
  result->total_ms = MsSince(t_start);
  return OkStatus();
}

}  // namespace holo
