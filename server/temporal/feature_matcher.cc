#include "server/temporal/feature_matcher.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "common/worker_pool.h"


namespace holo {

using Eigen::Vector3f;

Status FeatureMatchOptions::Check() const {
  if (max_features_per_pod < 1 || max_features_per_pod > 100000)
    return InvalidArgument("max_features_per_pod must be in [1, 100000], got " + std::to_string(max_features_per_pod));
  if (max_hamming < 0 || max_hamming > 256) return InvalidArgument("max_hamming must be in [0, 256]");
  if (!(ratio > 0 && ratio <= 1)) return InvalidArgument("ratio must be in (0, 1], got " + std::to_string(ratio));
  if (!(max_motion_m > 0 && max_motion_m < 10))
    return InvalidArgument("max_motion_m must be in (0, 10), got " + std::to_string(max_motion_m));
  if (depth_window_px < 0 || depth_window_px > 8) return InvalidArgument("depth_window_px must be in [0, 8]");
  if (mask_erode_px < 0 || mask_erode_px > 32) return InvalidArgument("mask_erode_px must be in [0, 32]");
  if (threads < 0 || threads > 256) return InvalidArgument("threads must be in [0, 256]");
  return OkStatus();
}

namespace {

// Keypoints of one pod with depth: world positions and their descriptors (rows).
struct PodFeatures {
  std::vector<Vector3f> world;
  cv::Mat descriptors;  // CV_8U, one row per entry of `world`
};

}  // namespace

struct FeatureMatcher::Impl {
  explicit Impl(int threads) : pool(threads) {}
  WorkerPool pool;
  std::vector<cv::Ptr<cv::ORB>> orb;  // one per pod (detectors keep state)
  std::vector<PodFeatures> prev, cur;
  bool has_prev = false;
};

FeatureMatcher::FeatureMatcher(FeatureMatchOptions options) : options_(options) {
  HOLO_CHECK(options_.Check().ok());
  impl_ = std::make_unique<Impl>(options_.threads);
}

FeatureMatcher::~FeatureMatcher() = default;

void FeatureMatcher::Reset() {
  impl_->has_prev = false;
  impl_->prev.clear();
}

Status FeatureMatcher::Match(const Rig& rig, const RgbdFrameSet& frames, std::vector<FeatureCorrespondence>* out) {
  out->clear();
  if (frames.frames.size() != rig.pods.size())
    return InvalidArgument("frame set has " + std::to_string(frames.frames.size()) + " pods but the rig has " +
                           std::to_string(rig.pods.size()));
  Impl& m = *impl_;
  m.cur.assign(rig.pods.size(), PodFeatures());
  last_keypoints_ = 0;
  const int r = options_.depth_window_px;
  while (m.orb.size() < rig.pods.size()) m.orb.push_back(cv::ORB::create(options_.max_features_per_pod));
  // Detection per pod in parallel (each pod writes only its own entry).
  m.pool.ParallelFor(static_cast<int>(rig.pods.size()), [&](int pi) {
    const size_t i = static_cast<size_t>(pi);
    const PodCalibration& cal = rig.pods[i];
    const RgbdFrame& f = frames.frames[i];
    const int w = cal.depth.width, h = cal.depth.height;
    if (!cal.IsRegistered() || cal.depth.HasDistortion()) return;
    if (f.color.empty() || f.depth.empty() || f.mask.empty()) return;
    if (f.color.width() != w || f.color.height() != h || f.depth.width() != w || f.depth.height() != h ||
        f.mask.width() != w || f.mask.height() != h)
      return;  // sizes differ from the calibration: this pod gives no features
    cv::Mat rgb(h, w, CV_8UC3, const_cast<uint8_t*>(f.color.data()));
    cv::Mat gray;
    cv::cvtColor(rgb, gray, cv::COLOR_RGB2GRAY);
    cv::Mat mask(h, w, CV_8U, const_cast<uint8_t*>(f.mask.data()));
    cv::Mat inner;
    if (options_.mask_erode_px > 0) {
      cv::erode(mask, inner, cv::Mat(), cv::Point(-1, -1), options_.mask_erode_px);
    } else {
      inner = mask;
    }
    std::vector<cv::KeyPoint> kps;
    cv::Mat desc;
    m.orb[i]->detectAndCompute(gray, inner, kps, desc);
    PodFeatures& pf = m.cur[i];
    const uint16_t* depth = f.depth.data();
    const uint8_t* mk = f.mask.data();
    const float fx = static_cast<float>(cal.depth.fx), fy = static_cast<float>(cal.depth.fy);
    const float cx = static_cast<float>(cal.depth.cx), cy = static_cast<float>(cal.depth.cy);
    std::vector<uint16_t> window;
    for (size_t k = 0; k < kps.size(); ++k) {
      const int u = static_cast<int>(std::lround(kps[k].pt.x)), v = static_cast<int>(std::lround(kps[k].pt.y));
      if (u < 0 || v < 0 || u >= w || v >= h) continue;
      window.clear();
      for (int y = std::max(0, v - r); y <= std::min(h - 1, v + r); ++y)
        for (int x = std::max(0, u - r); x <= std::min(w - 1, u + r); ++x) {
          const size_t p = static_cast<size_t>(y) * w + x;
          if (mk[p] != 0 && depth[p] != 0) window.push_back(depth[p]);
        }
      if (window.size() * 2 < static_cast<size_t>((2 * r + 1) * (2 * r + 1))) continue;  // edge or hole
      std::nth_element(window.begin(), window.begin() + window.size() / 2, window.end());
      const float z = window[window.size() / 2] * 0.001f;
      const Vector3f pc((kps[k].pt.x - cx) * z / fx, (kps[k].pt.y - cy) * z / fy, z);
      pf.world.push_back(cal.world_from_depth * pc);
      pf.descriptors.push_back(desc.row(static_cast<int>(k)));
    }
  });
  for (const PodFeatures& pf : m.cur) last_keypoints_ += pf.world.size();

  if (m.has_prev && m.prev.size() == m.cur.size()) {
    cv::BFMatcher matcher(cv::NORM_HAMMING);
    for (size_t i = 0; i < m.cur.size(); ++i) {
      const PodFeatures& a = m.prev[i];
      const PodFeatures& b = m.cur[i];
      if (a.world.size() < 2 || b.world.size() < 2) continue;
      std::vector<std::vector<cv::DMatch>> ab, ba;
      matcher.knnMatch(a.descriptors, b.descriptors, ab, 2);
      matcher.knnMatch(b.descriptors, a.descriptors, ba, 1);
      for (const auto& mm : ab) {
        if (mm.size() < 2) continue;
        const cv::DMatch& best = mm[0];
        if (best.distance > static_cast<float>(options_.max_hamming)) continue;
        if (best.distance >= options_.ratio * mm[1].distance) continue;
        const size_t qi = static_cast<size_t>(best.queryIdx), ti = static_cast<size_t>(best.trainIdx);
        if (ti >= ba.size() || ba[ti].empty() || static_cast<size_t>(ba[ti][0].trainIdx) != qi) continue;  // mutual
        const Vector3f& from = a.world[qi];
        const Vector3f& to = b.world[ti];
        if ((to - from).norm() > options_.max_motion_m) continue;
        out->push_back({from, to, static_cast<int>(i)});
      }
    }
  }
  std::swap(m.prev, m.cur);
  m.has_prev = true;
  return OkStatus();
}

}  // namespace holo
