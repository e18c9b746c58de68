#include "server/segment/color_calibration.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Cholesky>

namespace holo {
namespace {

// Per-pixel average of a static scene over several frame sets.
struct PodAverage {
  int w = 0, h = 0;    // depth camera
  int cw = 0, ch = 0;  // colour camera
  std::vector<float> depth_m;  // 0 = invalid in most frames
  std::vector<float> rgb;      // colour camera, 3 floats per pixel
  std::vector<uint8_t> rgb_max;  // per colour pixel: largest channel range over its 3×3 neighbourhood
};

PodAverage Average(const std::vector<RgbdFrameSet>& frames, size_t pod) {
  PodAverage a;
  const RgbdFrame& f0 = frames[0].frames[pod];
  a.w = f0.depth.width(), a.h = f0.depth.height();
  a.cw = f0.color.width(), a.ch = f0.color.height();
  const size_t n = static_cast<size_t>(a.w) * a.h, nc = static_cast<size_t>(a.cw) * a.ch;
  std::vector<float> sum(n, 0.0f);
  std::vector<int> count(n, 0);
  a.rgb.assign(nc * 3, 0.0f);
  for (const RgbdFrameSet& fs : frames) {
    const RgbdFrame& f = fs.frames[pod];
    for (size_t i = 0; i < n; ++i)
      if (f.depth.data()[i] > 0) sum[i] += f.depth.data()[i] * 0.001f, ++count[i];
    for (size_t i = 0; i < nc * 3; ++i) a.rgb[i] += f.color.data()[i];
  }
  a.depth_m.assign(n, 0.0f);
  const int need = static_cast<int>((frames.size() + 1) / 2);
  for (size_t i = 0; i < n; ++i)
    if (count[i] >= need) a.depth_m[i] = sum[i] / count[i];
  const float inv = 1.0f / static_cast<float>(frames.size());
  for (float& v : a.rgb) v *= inv;
  // Largest per-channel range over the 3×3 neighbourhood, per colour pixel.
  a.rgb_max.assign(nc, 255);
  for (int y = 1; y + 1 < a.ch; ++y)
    for (int x = 1; x + 1 < a.cw; ++x) {
      float range = 0;
      for (int c = 0; c < 3; ++c) {
        float lo = 1e9f, hi = -1e9f;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const float v = a.rgb[(static_cast<size_t>(y + dy) * a.cw + x + dx) * 3 + c];
            lo = std::min(lo, v), hi = std::max(hi, v);
          }
        range = std::max(range, hi - lo);
      }
      a.rgb_max[static_cast<size_t>(y) * a.cw + x] = static_cast<uint8_t>(std::min(255.0f, range));
    }
  return a;
}

// Largest depth step in the 3×3 neighbourhood of (x, y); infinity if any
// neighbour is invalid or outside.
float LocalDepthStep(const PodAverage& a, int x, int y) {
  if (x < 1 || y < 1 || x + 1 >= a.w || y + 1 >= a.h) return 1e9f;
  const float c = a.depth_m[static_cast<size_t>(y) * a.w + x];
  float step = 0;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const float v = a.depth_m[static_cast<size_t>(y + dy) * a.w + x + dx];
      if (v <= 0) return 1e9f;
      step = std::max(step, std::abs(v - c));
    }
  return step;
}

// Colour of the static scene at world point `p` seen by `cam` (bilinear),
// false if outside the image or in strong texture.
bool SampleColour(const PodAverage& a, const CameraModel& cam, const Eigen::Vector3f& p, int max_range,
                  Eigen::Vector3f* rgb) {
  Eigen::Vector2f px;
  if (!cam.ProjectWorld(p, &px)) return false;
  const int x0 = static_cast<int>(std::floor(px.x())), y0 = static_cast<int>(std::floor(px.y()));
  if (x0 < 1 || y0 < 1 || x0 + 2 >= a.cw || y0 + 2 >= a.ch) return false;
  const int xn = static_cast<int>(std::lround(px.x())), yn = static_cast<int>(std::lround(px.y()));
  if (a.rgb_max[static_cast<size_t>(yn) * a.cw + xn] > max_range) return false;
  const float fx = px.x() - x0, fy = px.y() - y0;
  auto at = [&](int x, int y) {
    const float* v = &a.rgb[(static_cast<size_t>(y) * a.cw + x) * 3];
    return Eigen::Vector3f(v[0], v[1], v[2]);
  };
  *rgb = (1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0)) + fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1));
  return true;
}

struct Pairs {
  std::vector<Eigen::Vector3f> pod, ref;
};

void CollectPairs(const PodCalibration& pod_cal, const PodAverage& pod, const PodCalibration& ref_cal,
                  const PodAverage& ref, const ColorCalibrationOptions& o, Pairs* out) {
  const CameraModel pod_depth = pod_cal.DepthCamera(), pod_colour = pod_cal.ColorCamera();
  const CameraModel ref_depth = ref_cal.DepthCamera(), ref_colour = ref_cal.ColorCamera();
  const Pose ref_from_world = ref_depth.world_from_camera.inverse();
  for (int y = 1; y + 1 < pod.h; y += o.stride) {
    for (int x = 1; x + 1 < pod.w; x += o.stride) {
      const float z = pod.depth_m[static_cast<size_t>(y) * pod.w + x];
      if (z <= 0 || LocalDepthStep(pod, x, y) > o.max_local_depth_step_m) continue;
      const Eigen::Vector3f p = pod_depth.UnprojectWorld(Eigen::Vector2f(static_cast<float>(x), static_cast<float>(y)), z);
      // Visible from the reference pod: its depth there agrees with the
      // point's depth in its camera.
      const Eigen::Vector3f pr = ref_from_world * p;
      Eigen::Vector2f q;
      if (!ref_depth.ProjectCamera(pr, &q)) continue;
      const int qx = static_cast<int>(std::lround(q.x())), qy = static_cast<int>(std::lround(q.y()));
      if (qx < 1 || qy < 1 || qx + 1 >= ref.w || qy + 1 >= ref.h) continue;
      const float zr = ref.depth_m[static_cast<size_t>(qy) * ref.w + qx];
      if (zr <= 0 || std::abs(zr - pr.z()) > o.depth_tolerance_m + o.depth_tolerance_rel * pr.z()) continue;
      if (LocalDepthStep(ref, qx, qy) > o.max_local_depth_step_m) continue;
      Eigen::Vector3f ca, cr;
      if (!SampleColour(pod, pod_colour, p, o.max_local_colour_range, &ca)) continue;
      if (!SampleColour(ref, ref_colour, p, o.max_local_colour_range, &cr)) continue;
      if (ca.minCoeff() < o.min_level || cr.minCoeff() < o.min_level || ca.maxCoeff() > o.max_level ||
          cr.maxCoeff() > o.max_level)
        continue;
      out->pod.push_back(ca);
      out->ref.push_back(cr);
    }
  }
}

// Colour pairs between pods i < j: the same surface point seen by both.
struct Edge {
  int i = 0, j = 0;
  Pairs pairs;
};

// Joint robust fit of every pod's map so that M_i · [c_i; 1] ≈ M_j · [c_j; 1]
// over all edges, with M_ref fixed to the identity. The channels decouple:
// per output channel c the unknowns are row c of every non-reference map
// (4 numbers for a full map, gain and offset otherwise). Huber IRLS; a tiny
// ridge towards the identity keeps the normal equations regular.
std::vector<Eigen::Matrix<float, 3, 4>> FitMaps(const std::vector<Edge>& edges, int num_pods, int ref,
                                                const ColorCalibrationOptions& o) {
  const int k = o.full_matrix ? 4 : 2;
  std::vector<int> block(num_pods, -1);
  int num_blocks = 0;
  for (int p = 0; p < num_pods; ++p)
    if (p != ref) block[p] = num_blocks++;
  std::vector<Eigen::Matrix<float, 3, 4>> maps(num_pods, Eigen::Matrix<float, 3, 4>::Zero());
  for (auto& m : maps) m.leftCols<3>().setIdentity();
  const int n = k * num_blocks;
  for (int c = 0; c < 3; ++c) {
    // Parameters of row c of pod p's map, and the feature of a colour.
    auto feature = [&](const Eigen::Vector3f& x, Eigen::Vector4d* f) {
      if (o.full_matrix)
        *f << x.x(), x.y(), x.z(), 1.0;
      else
        *f << x[c], 1.0, 0.0, 0.0;
    };
    Eigen::Vector4d identity_row = Eigen::Vector4d::Zero();
    identity_row[o.full_matrix ? c : 0] = 1.0;
    Eigen::VectorXd theta(n);
    for (int b = 0; b < num_blocks; ++b) theta.segment(b * k, k) = identity_row.head(k);
    auto row_of = [&](int p) -> Eigen::Vector4d {
      if (p == ref) return identity_row;
      Eigen::Vector4d r = Eigen::Vector4d::Zero();
      r.head(k) = theta.segment(block[p] * k, k);
      return r;
    };
    for (int it = 0; it <= o.irls_iterations; ++it) {
      Eigen::MatrixXd ata = Eigen::MatrixXd::Zero(n, n);
      Eigen::VectorXd atb = Eigen::VectorXd::Zero(n);
      for (const Edge& e : edges) {
        const Eigen::Vector4d ri = row_of(e.i), rj = row_of(e.j);
        const int bi = block[e.i], bj = block[e.j];
        for (size_t q = 0; q < e.pairs.pod.size(); ++q) {
          Eigen::Vector4d fi, fj;
          feature(e.pairs.pod[q], &fi);  // pod[] holds pod i's colour, ref[] pod j's
          feature(e.pairs.ref[q], &fj);
          double w = 1.0;
          if (it > 0) {
            const double r = std::abs(ri.dot(fi) - rj.dot(fj));
            if (r > o.huber_delta) w = o.huber_delta / r;
          }
          // Residual r = row_i·f_i − row_j·f_j = J θ − y.
          double y = 0;
          if (bi < 0) y -= identity_row.dot(fi);
          if (bj < 0) y += identity_row.dot(fj);
          if (bi >= 0) {
            ata.block(bi * k, bi * k, k, k).noalias() += w * fi.head(k) * fi.head(k).transpose();
            atb.segment(bi * k, k) += w * y * fi.head(k);
          }
          if (bj >= 0) {
            ata.block(bj * k, bj * k, k, k).noalias() += w * fj.head(k) * fj.head(k).transpose();
            atb.segment(bj * k, k) -= w * y * fj.head(k);
          }
          if (bi >= 0 && bj >= 0) {
            const Eigen::Matrix4d cross = w * fi * fj.transpose();
            ata.block(bi * k, bj * k, k, k) -= cross.topLeftCorner(k, k);
            ata.block(bj * k, bi * k, k, k) -= cross.topLeftCorner(k, k).transpose();
          }
        }
      }
      const double ridge = 1e-6 * (ata.diagonal().maxCoeff() + 1.0);
      for (int b = 0; b < num_blocks; ++b)
        for (int t = 0; t < k; ++t) {
          ata(b * k + t, b * k + t) += ridge;
          atb[b * k + t] += ridge * identity_row[t];
        }
      theta = ata.ldlt().solve(atb);
    }
    for (int p = 0; p < num_pods; ++p) {
      if (p == ref) continue;
      const Eigen::VectorXd row = theta.segment(block[p] * k, k);
      if (o.full_matrix) {
        for (int t = 0; t < 4; ++t) maps[p](c, t) = static_cast<float>(row[t]);
      } else {
        maps[p](c, c) = static_cast<float>(row[0]);
        maps[p](c, 3) = static_cast<float>(row[1]);
      }
    }
  }
  return maps;
}

Eigen::Matrix<float, 3, 4> IdentityMap() {
  Eigen::Matrix<float, 3, 4> m = Eigen::Matrix<float, 3, 4>::Zero();
  m.leftCols<3>().setIdentity();
  return m;
}

}  // namespace

Status ColorCalibrationOptions::Check() const {
  if (!(depth_tolerance_m >= 0) || !(depth_tolerance_rel >= 0))
    return InvalidArgument("depth tolerances must be >= 0, got " + std::to_string(depth_tolerance_m) + ", " +
                           std::to_string(depth_tolerance_rel));
  if (!(max_local_depth_step_m > 0))
    return InvalidArgument("max_local_depth_step_m must be > 0, got " + std::to_string(max_local_depth_step_m));
  if (max_local_colour_range < 0 || max_local_colour_range > 255)
    return InvalidArgument("max_local_colour_range must be in 0..255, got " + std::to_string(max_local_colour_range));
  if (min_level < 0 || max_level > 255 || min_level >= max_level)
    return InvalidArgument("need 0 <= min_level < max_level <= 255, got " + std::to_string(min_level) + ", " +
                           std::to_string(max_level));
  if (stride < 1) return InvalidArgument("stride must be >= 1, got " + std::to_string(stride));
  if (min_pairs < 8) return InvalidArgument("min_pairs must be >= 8, got " + std::to_string(min_pairs));
  if (min_edge_pairs < 1) return InvalidArgument("min_edge_pairs must be >= 1, got " + std::to_string(min_edge_pairs));
  if (!(huber_delta > 0)) return InvalidArgument("huber_delta must be > 0, got " + std::to_string(huber_delta));
  if (irls_iterations < 0 || irls_iterations > 100)
    return InvalidArgument("irls_iterations must be in 0..100, got " + std::to_string(irls_iterations));
  return OkStatus();
}

ColorCalibration ColorCalibration::Identity(int num_pods, int reference_pod) {
  ColorCalibration c;
  c.reference_pod = reference_pod;
  c.pod_to_reference.assign(static_cast<size_t>(std::max(0, num_pods)), IdentityMap());
  return c;
}

Eigen::Vector3f ColorCalibration::Map(int pod, const Eigen::Vector3f& rgb) const {
  HOLO_CHECK(pod >= 0 && static_cast<size_t>(pod) < pod_to_reference.size());
  const auto& m = pod_to_reference[static_cast<size_t>(pod)];
  return m.leftCols<3>() * rgb + m.col(3);
}

void ColorCalibration::Apply(RgbdFrameSet* frames) const {
  HOLO_CHECK_MSG(frames->frames.size() == pod_to_reference.size(),
                 "ColorCalibration::Apply: " + std::to_string(pod_to_reference.size()) + " maps for " +
                     std::to_string(frames->frames.size()) + " pods");
  // Fixed point (1/256) tables: out_c = Σ_k T[c][k][in_k] + offset_c.
  int32_t table[3][3][256];
  for (size_t p = 0; p < frames->frames.size(); ++p) {
    const auto& m = pod_to_reference[p];
    if ((m - IdentityMap()).isZero(1e-7f)) continue;
    for (int c = 0; c < 3; ++c)
      for (int k = 0; k < 3; ++k)
        for (int v = 0; v < 256; ++v) {
          float t = m(c, k) * static_cast<float>(v) * 256.0f;
          if (k == 0) t += (m(c, 3) + 0.5f) * 256.0f;  // offset and rounding folded into the first table
          table[c][k][v] = static_cast<int32_t>(std::lround(t));
        }
    ImageRgb8& img = frames->frames[p].color;
    uint8_t* px = img.data();
    const size_t n = img.num_pixels();
    for (size_t i = 0; i < n; ++i, px += 3) {
      const int r = px[0], g = px[1], b = px[2];
      for (int c = 0; c < 3; ++c) {
        const int32_t v = (table[c][0][r] + table[c][1][g] + table[c][2][b]) >> 8;
        px[c] = static_cast<uint8_t>(std::clamp(v, 0, 255));
      }
    }
  }
}

StatusOr<ColorCalibration> EstimateColorCalibration(const Rig& rig, const std::vector<RgbdFrameSet>& frames,
                                                    int reference_pod, const ColorCalibrationOptions& options,
                                                    ColorCalibrationStats* stats) {
  HOLO_RETURN_IF_ERROR(options.Check());
  const size_t num_pods = rig.pods.size();
  if (frames.empty()) return InvalidArgument("EstimateColorCalibration: no frames");
  if (reference_pod < 0 || static_cast<size_t>(reference_pod) >= num_pods)
    return InvalidArgument("EstimateColorCalibration: reference_pod " + std::to_string(reference_pod) +
                           " is not a pod of the rig (" + std::to_string(num_pods) + " pods)");
  for (size_t k = 0; k < frames.size(); ++k) {
    if (frames[k].frames.size() != num_pods)
      return InvalidArgument("EstimateColorCalibration: frame set " + std::to_string(k) + " has " +
                             std::to_string(frames[k].frames.size()) + " pods, the rig has " + std::to_string(num_pods));
    for (size_t p = 0; p < num_pods; ++p) {
      const RgbdFrame& f = frames[k].frames[p];
      const PodCalibration& c = rig.pods[p];
      if (f.depth.width() != c.depth.width || f.depth.height() != c.depth.height || f.color.width() != c.color.width ||
          f.color.height() != c.color.height)
        return InvalidArgument("EstimateColorCalibration: frame set " + std::to_string(k) + " pod " +
                               std::to_string(p) + " has depth " + std::to_string(f.depth.width()) + "x" +
                               std::to_string(f.depth.height()) + " and colour " + std::to_string(f.color.width()) +
                               "x" + std::to_string(f.color.height()) + ", the rig says " +
                               std::to_string(c.depth.width) + "x" + std::to_string(c.depth.height) + " and " +
                               std::to_string(c.color.width) + "x" + std::to_string(c.color.height));
    }
  }
  std::vector<PodAverage> avg(num_pods);
  for (size_t p = 0; p < num_pods; ++p) avg[p] = Average(frames, p);

  ColorCalibration calib = ColorCalibration::Identity(static_cast<int>(num_pods), reference_pod);
  if (stats) {
    stats->pairs.assign(num_pods, 0);
    stats->residual_before.assign(num_pods, 0.0);
    stats->residual_after.assign(num_pods, 0.0);
  }
  // Pairs between every two pods that see common surface.
  std::vector<Edge> edges;
  std::vector<int> pod_pairs(num_pods, 0);
  for (size_t i = 0; i < num_pods; ++i)
    for (size_t j = i + 1; j < num_pods; ++j) {
      Edge e;
      e.i = static_cast<int>(i), e.j = static_cast<int>(j);
      CollectPairs(rig.pods[i], avg[i], rig.pods[j], avg[j], options, &e.pairs);
      if (e.pairs.pod.size() < static_cast<size_t>(options.min_edge_pairs)) continue;
      pod_pairs[i] += static_cast<int>(e.pairs.pod.size());
      pod_pairs[j] += static_cast<int>(e.pairs.pod.size());
      edges.push_back(std::move(e));
    }
  // Every pod must be connected to the reference through overlapping views.
  std::vector<bool> reached(num_pods, false);
  reached[reference_pod] = true;
  for (bool grew = true; grew;) {
    grew = false;
    for (const Edge& e : edges)
      if (reached[e.i] != reached[e.j]) reached[e.i] = reached[e.j] = grew = true;
  }
  for (size_t p = 0; p < num_pods; ++p) {
    if (pod_pairs[p] < options.min_pairs || !reached[p])
      return InvalidArgument("EstimateColorCalibration: pod " + std::to_string(p) + " shares " +
                             std::to_string(pod_pairs[p]) + " usable surface points with other pods" +
                             (reached[p] ? "" : " and none connect it to reference pod " +
                                                    std::to_string(reference_pod)) +
                             ", need " + std::to_string(options.min_pairs));
  }
  calib.pod_to_reference = FitMaps(edges, static_cast<int>(num_pods), reference_pod, options);
  if (stats) {
    std::vector<double> before(num_pods, 0.0), after(num_pods, 0.0);
    for (const Edge& e : edges)
      for (size_t q = 0; q < e.pairs.pod.size(); ++q) {
        const double b = (e.pairs.pod[q] - e.pairs.ref[q]).cwiseAbs().mean();
        const double a = (calib.Map(e.i, e.pairs.pod[q]) - calib.Map(e.j, e.pairs.ref[q])).cwiseAbs().mean();
        before[e.i] += b, before[e.j] += b, after[e.i] += a, after[e.j] += a;
      }
    for (size_t p = 0; p < num_pods; ++p) {
      stats->pairs[p] = pod_pairs[p];
      stats->residual_before[p] = before[p] / std::max(1, pod_pairs[p]);
      stats->residual_after[p] = after[p] / std::max(1, pod_pairs[p]);
    }
  }
  return calib;
}

}  // namespace holo
