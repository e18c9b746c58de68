// Analytic test scenes for fusion tests: ray casters for a sphere and a box,
// a ring of pods around a point, and exact depth renders of a scene.
#pragma once

#include <array>
#include <cmath>
#include <functional>
#include <optional>
#include <string>

#include <Eigen/Geometry>

#include "common/pose.h"
#include "common/rgbd.h"
#include "common/rig.h"

namespace holo {

// Distance along a unit ray (origin o, direction d) to the first hit, if any.
using RayCaster = std::function<std::optional<float>(const Eigen::Vector3f& o, const Eigen::Vector3f& d)>;

inline RayCaster Sphere(const Eigen::Vector3f& c, float r) {
  return [c, r](const Eigen::Vector3f& o, const Eigen::Vector3f& d) -> std::optional<float> {
    const Eigen::Vector3f oc = o - c;
    const float b = oc.dot(d), q = oc.squaredNorm() - r * r, disc = b * b - q;
    if (disc < 0) return std::nullopt;
    const float t = -b - std::sqrt(disc);
    if (t <= 0) return std::nullopt;
    return t;
  };
}

inline RayCaster Box(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  return [lo, hi](const Eigen::Vector3f& o, const Eigen::Vector3f& d) -> std::optional<float> {
    float t0 = 0, t1 = INFINITY;
    for (int a = 0; a < 3; ++a) {
      const float inv = 1.0f / d[a];
      float ta = (lo[a] - o[a]) * inv, tb = (hi[a] - o[a]) * inv;
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    if (t0 > t1 || t0 <= 0) return std::nullopt;
    return t0;
  };
}

// `n` pods on a ring of radius `radius` around `center`, alternating
// heights, looking at the centre.
inline Rig RingRig(int n, const Eigen::Vector3f& center, float radius, int width = 160, int height = 120) {
  Rig rig;
  rig.name = "ring";
  for (int k = 0; k < n; ++k) {
    PodCalibration pod;
    pod.id = k;
    pod.name = "cam" + std::to_string(k);
    pod.depth = pod.color = Intrinsics::FromFov(width, height, 60.0);
    const float a = 2.0f * static_cast<float>(M_PI) * static_cast<float>(k) / static_cast<float>(n);
    const Eigen::Vector3f eye = center + Eigen::Vector3f(radius * std::cos(a), radius * std::sin(a), (k % 2 ? 0.6f : -0.5f));
    pod.world_from_depth = LookAt(eye, center);
    rig.pods.push_back(pod);
  }
  return rig;
}

// Exact (noise-free, mm-rounded) depth of `scene` from every pod; constant colour.
inline RgbdFrameSet RenderAnalytic(const Rig& rig, const RayCaster& scene, std::array<uint8_t, 3> color = {200, 120, 40}) {
  RgbdFrameSet set;
  for (const PodCalibration& pod : rig.pods) {
    RgbdFrame f;
    f.pod_id = pod.id;
    f.depth.Resize(pod.depth.width, pod.depth.height);
    f.color.Resize(pod.color.width, pod.color.height);
    for (int y = 0; y < f.color.height(); ++y)
      for (int x = 0; x < f.color.width(); ++x)
        for (int c = 0; c < 3; ++c) f.color.at(x, y, c) = color[static_cast<size_t>(c)];
    const CameraModel cam = pod.DepthCamera();
    for (int y = 0; y < f.depth.height(); ++y)
      for (int x = 0; x < f.depth.width(); ++x) {
        const Eigen::Vector2f px(static_cast<float>(x), static_cast<float>(y));
        const Eigen::Vector3f ray_cam = cam.UnprojectCamera(px, 1.0f);  // z = 1
        const Eigen::Vector3f d = (cam.world_from_camera.linear() * ray_cam).normalized();
        if (auto t = scene(cam.Center(), d)) {
          const float z = *t / ray_cam.norm();
          f.depth.at(x, y) = static_cast<uint16_t>(std::lround(z * 1000.0f));
        }
      }
    set.frames.push_back(std::move(f));
  }
  return set;
}

}  // namespace holo
