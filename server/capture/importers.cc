#include "server/capture/importers.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <string_view>
#include <system_error>
#include <utility>

#include <nlohmann/json.hpp>

#include "common/file_util.h"
#include "common/image_io.h"

namespace holo {
namespace {

// Text index files (rgb.txt, trajectory.log, ...) larger than this are refused.
constexpr uintmax_t kMaxTextFileBytes = 64u << 20;
// A rig holds at most this many pods (Rig::Check).
constexpr size_t kMaxPods = 64;

StatusOr<std::string> ReadTextFile(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return NotFound(path + ": file not found");
  const uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) return Unavailable(path + ": cannot stat: " + ec.message());
  if (size > kMaxTextFileBytes)
    return DataLoss(path + ": " + std::to_string(size) + " bytes, more than the limit of " +
                    std::to_string(kMaxTextFileBytes));
  return ReadFileToString(path);
}

// Whitespace-separated tokens of one line.
std::vector<std::string_view> Tokens(std::string_view line) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    const size_t start = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
  return out;
}

bool ParseDouble(std::string_view s, double* out) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && end == s.data() + s.size() && std::isfinite(*out);
}

bool ParseInt64(std::string_view s, int64_t* out) {
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && end == s.data() + s.size();
}

std::string Quote(std::string_view s) {
  std::string out(1, '\'');
  out.append(s.substr(0, 60));
  out.push_back('\'');
  return out;
}

// Calls `fn(line_no, line)` for every line; stops at the first error.
template <typename Fn>
Status ForEachLine(const std::string& text, Fn fn) {
  size_t pos = 0;
  int64_t line_no = 0;
  while (pos < text.size()) {
    size_t eol = text.find('\n', pos);
    if (eol == std::string::npos) eol = text.size();
    std::string_view line = std::string_view(text).substr(pos, eol - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos = eol + 1;
    HOLO_RETURN_IF_ERROR(fn(++line_no, line));
  }
  return OkStatus();
}

bool IsSafeRelativePath(std::string_view p) {
  if (p.empty() || p.front() == '/') return false;
  const std::filesystem::path path{std::string(p)};
  for (const auto& part : path)
    if (part == "..") return false;
  return true;
}

// Converts depth in `units_per_metre` to millimetres in place; values that do
// not fit in 16 bits become 0 (invalid).
void ConvertDepthToMm(ImageDepth16* depth, double units_per_metre) {
  if (units_per_metre == 1000.0) return;
  const double scale = 1000.0 / units_per_metre;
  for (uint16_t& d : depth->storage()) {
    const double mm = std::round(d * scale);
    d = mm > 65535.0 ? 0 : static_cast<uint16_t>(mm);
  }
}

template <typename T, int C>
Status CheckImageSize(const Image<T, C>& image, int w, int h, const std::string& path, const std::string& source) {
  if (image.width() == w && image.height() == h) return OkStatus();
  return DataLoss(path + ": image is " + std::to_string(image.width()) + "x" + std::to_string(image.height()) + ", " +
                  source + " says " + std::to_string(w) + "x" + std::to_string(h));
}

Status CheckUnits(double units_per_metre) {
  if (!(units_per_metre > 0) || !std::isfinite(units_per_metre))
    return InvalidArgument("depth_units_per_metre must be > 0, got " + std::to_string(units_per_metre));
  return OkStatus();
}

// Resolves `options.frames` against `available` items.
StatusOr<std::vector<size_t>> SelectFrames(const std::vector<int>& frames, size_t available, const std::string& what) {
  std::vector<size_t> out;
  if (frames.empty()) {
    if (available > kMaxPods)
      return InvalidArgument(what + ": " + std::to_string(available) + " frames, more than the " +
                             std::to_string(kMaxPods) + " pods of a rig; select some with options.frames");
    for (size_t i = 0; i < available; ++i) out.push_back(i);
  } else {
    if (frames.size() > kMaxPods)
      return InvalidArgument("options.frames selects " + std::to_string(frames.size()) + " frames, at most " +
                             std::to_string(kMaxPods));
    for (size_t k = 0; k < frames.size(); ++k) {
      if (frames[k] < 0 || static_cast<size_t>(frames[k]) >= available)
        return InvalidArgument("options.frames[" + std::to_string(k) + "] = " + std::to_string(frames[k]) +
                               " is out of range: " + what + " has " + std::to_string(available) + " frames");
      out.push_back(static_cast<size_t>(frames[k]));
    }
  }
  if (out.empty()) return DataLoss(what + ": no frames to import");
  return out;
}

PodCalibration MakePod(int id, const std::string& name, const Intrinsics& k, const Pose& world_from_depth) {
  PodCalibration pod;
  pod.id = id;
  pod.name = name;
  pod.depth = k;
  pod.color = k;
  pod.color_from_depth = Pose::Identity();
  pod.world_from_depth = world_from_depth;
  return pod;
}

// ---------------------------------------------------------------------------
// TUM

struct TimedFile {
  double t = 0;
  std::string file;
  int64_t line = 0;
};

Status ParseTumList(const std::string& path, std::vector<TimedFile>* out) {
  HOLO_ASSIGN_OR_RETURN(const std::string text, ReadTextFile(path));
  out->clear();
  HOLO_RETURN_IF_ERROR(ForEachLine(text, [&](int64_t n, std::string_view line) -> Status {
    const auto tok = Tokens(line);
    if (tok.empty() || tok[0].front() == '#') return OkStatus();
    const std::string at = path + ":" + std::to_string(n) + ": ";
    if (tok.size() != 2) return DataLoss(at + "expected 'timestamp filename', got " + std::to_string(tok.size()) + " fields");
    TimedFile f;
    if (!ParseDouble(tok[0], &f.t) || f.t < 0) return DataLoss(at + "bad timestamp " + Quote(tok[0]));
    if (!IsSafeRelativePath(tok[1]))
      return DataLoss(at + "file name must be a relative path inside the folder, got " + Quote(tok[1]));
    f.file = std::string(tok[1]);
    f.line = n;
    out->push_back(std::move(f));
    return OkStatus();
  }));
  std::stable_sort(out->begin(), out->end(), [](const TimedFile& a, const TimedFile& b) { return a.t < b.t; });
  return OkStatus();
}

struct TimedPose {
  double t = 0;
  Eigen::Vector3d translation;
  Eigen::Quaterniond rotation;
};

Status ParseTumGroundTruth(const std::string& path, std::vector<TimedPose>* out) {
  HOLO_ASSIGN_OR_RETURN(const std::string text, ReadTextFile(path));
  out->clear();
  HOLO_RETURN_IF_ERROR(ForEachLine(text, [&](int64_t n, std::string_view line) -> Status {
    const auto tok = Tokens(line);
    if (tok.empty() || tok[0].front() == '#') return OkStatus();
    const std::string at = path + ":" + std::to_string(n) + ": ";
    if (tok.size() != 8)
      return DataLoss(at + "expected 'timestamp tx ty tz qx qy qz qw', got " + std::to_string(tok.size()) + " fields");
    double v[8];
    for (int i = 0; i < 8; ++i)
      if (!ParseDouble(tok[static_cast<size_t>(i)], &v[i])) return DataLoss(at + "field " + std::to_string(i + 1) + " is not a number: " + Quote(tok[static_cast<size_t>(i)]));
    TimedPose p;
    p.t = v[0];
    p.translation = Eigen::Vector3d(v[1], v[2], v[3]);
    p.rotation = Eigen::Quaterniond(v[7], v[4], v[5], v[6]);  // Eigen order: w, x, y, z
    const double norm = p.rotation.norm();
    if (std::abs(norm - 1.0) > 1e-2)
      return DataLoss(at + "quaternion is not unit length (norm " + std::to_string(norm) + ")");
    p.rotation.normalize();
    out->push_back(p);
    return OkStatus();
  }));
  std::stable_sort(out->begin(), out->end(), [](const TimedPose& a, const TimedPose& b) { return a.t < b.t; });
  return OkStatus();
}

Pose ToPose(const Eigen::Vector3d& t, const Eigen::Quaterniond& q) {
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  p.linear() = q.toRotationMatrix();
  p.translation() = t;
  return p.cast<float>();
}

// Pose at `t`: interpolated between the bracketing poses, else the nearest one.
bool PoseAt(const std::vector<TimedPose>& poses, double t, double max_dt, Pose* out) {
  if (poses.empty()) return false;
  const auto it = std::lower_bound(poses.begin(), poses.end(), t, [](const TimedPose& p, double v) { return p.t < v; });
  const size_t b = static_cast<size_t>(it - poses.begin());
  if (b < poses.size() && poses[b].t == t) {
    *out = ToPose(poses[b].translation, poses[b].rotation);
    return true;
  }
  if (b > 0 && b < poses.size()) {
    const TimedPose& p0 = poses[b - 1];
    const TimedPose& p1 = poses[b];
    if (t - p0.t <= max_dt && p1.t - t <= max_dt) {
      const double s = (t - p0.t) / (p1.t - p0.t);
      *out = ToPose((1 - s) * p0.translation + s * p1.translation, p0.rotation.slerp(s, p1.rotation));
      return true;
    }
  }
  const TimedPose* best = nullptr;
  if (b > 0) best = &poses[b - 1];
  if (b < poses.size() && (best == nullptr || poses[b].t - t < t - best->t)) best = &poses[b];
  if (best == nullptr || std::abs(best->t - t) > max_dt) return false;
  *out = ToPose(best->translation, best->rotation);
  return true;
}

// One-to-one association: each candidate pair within `max_dt`, closest first.
std::vector<std::pair<size_t, size_t>> Associate(const std::vector<TimedFile>& depth, const std::vector<TimedFile>& rgb,
                                                 double max_dt) {
  struct Candidate {
    double dt;
    size_t d, r;
  };
  std::vector<Candidate> cands;
  for (size_t d = 0; d < depth.size(); ++d) {
    const double t = depth[d].t;
    auto it = std::lower_bound(rgb.begin(), rgb.end(), t - max_dt, [](const TimedFile& f, double v) { return f.t < v; });
    for (; it != rgb.end() && it->t <= t + max_dt; ++it)
      cands.push_back({std::abs(it->t - t), d, static_cast<size_t>(it - rgb.begin())});
  }
  std::stable_sort(cands.begin(), cands.end(), [](const Candidate& a, const Candidate& b) { return a.dt < b.dt; });
  std::vector<bool> used_d(depth.size(), false), used_r(rgb.size(), false);
  std::vector<std::pair<size_t, size_t>> pairs;
  for (const auto& c : cands) {
    if (used_d[c.d] || used_r[c.r]) continue;
    used_d[c.d] = used_r[c.r] = true;
    pairs.emplace_back(c.d, c.r);
  }
  std::sort(pairs.begin(), pairs.end());  // depth time order
  return pairs;
}

}  // namespace

// ---------------------------------------------------------------------------

TumImportOptions TumImportOptions::Freiburg(int sequence) {
  TumImportOptions o;
  switch (sequence) {
    case 1: o.fx = 517.3; o.fy = 516.5; o.cx = 318.6; o.cy = 255.3; break;
    case 2: o.fx = 520.9; o.fy = 521.0; o.cx = 325.1; o.cy = 249.7; break;
    case 3: o.fx = 535.4; o.fy = 539.2; o.cx = 320.1; o.cy = 247.6; break;
    default: break;
  }
  return o;
}

Status TumImportOptions::Check() const {
  for (const auto& [name, v] : {std::pair{"fx", fx}, std::pair{"fy", fy}})
    if (!(v > 0) || !std::isfinite(v)) return InvalidArgument(std::string(name) + " must be > 0, got " + std::to_string(v));
  if (!std::isfinite(cx) || !std::isfinite(cy)) return InvalidArgument("cx and cy must be finite");
  HOLO_RETURN_IF_ERROR(CheckUnits(depth_units_per_metre));
  if (!(max_time_difference_s >= 0) || !std::isfinite(max_time_difference_s))
    return InvalidArgument("max_time_difference_s must be >= 0, got " + std::to_string(max_time_difference_s));
  if (!(max_pose_time_difference_s >= 0) || !std::isfinite(max_pose_time_difference_s))
    return InvalidArgument("max_pose_time_difference_s must be >= 0, got " +
                           std::to_string(max_pose_time_difference_s));
  return OkStatus();
}

StatusOr<ImportedScene> ImportTum(const std::string& dir, const TumImportOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check().WithContext("TumImportOptions"));
  std::vector<TimedFile> rgb, depth;
  HOLO_RETURN_IF_ERROR(ParseTumList(dir + "/rgb.txt", &rgb));
  HOLO_RETURN_IF_ERROR(ParseTumList(dir + "/depth.txt", &depth));
  const auto pairs = Associate(depth, rgb, options.max_time_difference_s);
  if (pairs.empty())
    return DataLoss(dir + "/depth.txt: no depth image has an rgb.txt image within " +
                    std::to_string(options.max_time_difference_s) + " s (" + std::to_string(depth.size()) +
                    " depth, " + std::to_string(rgb.size()) + " rgb entries)");
  HOLO_ASSIGN_OR_RETURN(const std::vector<size_t> selected,
                        SelectFrames(options.frames, pairs.size(), dir + " (associated rgb/depth pairs)"));

  std::vector<TimedPose> poses;
  const std::string gt_path = dir + "/groundtruth.txt";
  const bool has_gt = FileExists(gt_path);
  if (has_gt) HOLO_RETURN_IF_ERROR(ParseTumGroundTruth(gt_path, &poses));
  else if (options.require_poses) return NotFound(gt_path + ": file not found (options.require_poses is set)");
  if (has_gt && poses.empty()) return DataLoss(gt_path + ": no poses");

  ImportedScene scene;
  scene.rig.name = "tum:" + std::filesystem::path(dir).filename().string();
  scene.has_poses = has_gt;
  Intrinsics k;
  k.fx = options.fx;
  k.fy = options.fy;
  k.cx = options.cx;
  k.cy = options.cy;
  for (size_t i = 0; i < selected.size(); ++i) {
    const TimedFile& d = depth[pairs[selected[i]].first];
    const TimedFile& r = rgb[pairs[selected[i]].second];
    RgbdFrame f;
    f.pod_id = static_cast<int>(i);
    f.timestamp_us = std::llround(d.t * 1e6);
    const std::string depth_path = dir + "/" + d.file;
    const std::string rgb_path = dir + "/" + r.file;
    HOLO_RETURN_IF_ERROR(ReadDepth16(depth_path, &f.depth));
    HOLO_RETURN_IF_ERROR(ReadImageRgb8(rgb_path, &f.color));
    if (i == 0) {
      k.width = f.depth.width();
      k.height = f.depth.height();
    }
    HOLO_RETURN_IF_ERROR(CheckImageSize(f.depth, k.width, k.height, depth_path, "the first depth image"));
    HOLO_RETURN_IF_ERROR(CheckImageSize(f.color, k.width, k.height, rgb_path, "its depth image"));
    ConvertDepthToMm(&f.depth, options.depth_units_per_metre);
    Pose pose = Pose::Identity();
    if (has_gt && !PoseAt(poses, d.t, options.max_pose_time_difference_s, &pose))
      return DataLoss(gt_path + ": no pose within " + std::to_string(options.max_pose_time_difference_s) +
                      " s of depth timestamp " + std::string(std::to_string(d.t)) + " (depth.txt line " +
                      std::to_string(d.line) + ")");
    scene.rig.pods.push_back(MakePod(static_cast<int>(i), "tum_" + std::filesystem::path(d.file).stem().string(), k, pose));
    scene.frames.frames.push_back(std::move(f));
    scene.source_files.push_back(d.file);
  }
  HOLO_RETURN_IF_ERROR(scene.rig.Check().WithContext(dir + " (intrinsics from TumImportOptions)"));
  return scene;
}

// ---------------------------------------------------------------------------
// Redwood / Open3D

StatusOr<std::vector<Pose>> ParseRedwoodTrajectory(const std::string& text, const std::string& name) {
  std::vector<Pose> poses;
  Eigen::Matrix4d m;
  int row = -1;  // -1: expecting a block header
  int64_t block_line = 0;
  HOLO_RETURN_IF_ERROR(ForEachLine(text, [&](int64_t n, std::string_view line) -> Status {
    const auto tok = Tokens(line);
    if (tok.empty()) return OkStatus();
    const std::string at = name + ":" + std::to_string(n) + ": ";
    if (row < 0) {
      int64_t ids[3];
      if (tok.size() != 3 || !ParseInt64(tok[0], &ids[0]) || !ParseInt64(tok[1], &ids[1]) ||
          !ParseInt64(tok[2], &ids[2]))
        return DataLoss(at + "expected a block header of 3 integers ('id id id+1'), got " + Quote(line));
      if (poses.size() >= 1'000'000) return DataLoss(at + "more than 1000000 poses");
      row = 0;
      block_line = n;
      return OkStatus();
    }
    if (tok.size() != 4)
      return DataLoss(at + "expected 4 numbers in matrix row " + std::to_string(row + 1) + ", got " +
                      std::to_string(tok.size()));
    for (int c = 0; c < 4; ++c)
      if (!ParseDouble(tok[static_cast<size_t>(c)], &m(row, c)))
        return DataLoss(at + "not a number: " + Quote(tok[static_cast<size_t>(c)]));
    if (++row < 4) return OkStatus();
    row = -1;
    const std::string blk = name + ":" + std::to_string(block_line) + ": ";
    if (!m.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1), 1e-6) || std::abs(m(3, 3) - 1.0) > 1e-6)
      return DataLoss(blk + "last matrix row must be 0 0 0 1");
    const Eigen::Matrix3d r = m.topLeftCorner<3, 3>();
    if (!(r.transpose() * r).isApprox(Eigen::Matrix3d::Identity(), 1e-3) || r.determinant() < 0)
      return DataLoss(blk + "matrix is not a rigid transform (rotation not orthonormal)");
    Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
    p.linear() = r;
    p.translation() = m.topRightCorner<3, 1>();
    poses.push_back(p.cast<float>());
    return OkStatus();
  }));
  if (row >= 0)
    return DataLoss(name + ":" + std::to_string(block_line) + ": truncated: the block has " + std::to_string(row) +
                    " of 4 matrix rows");
  return poses;
}

StatusOr<Intrinsics> ParseOpen3dIntrinsicJson(const std::string& text, const std::string& name) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return DataLoss(name + ": not valid JSON");
  if (!j.is_object()) return DataLoss(name + ": expected a JSON object");
  Intrinsics k;
  for (const char* key : {"width", "height"}) {
    const auto it = j.find(key);
    if (it == j.end()) return DataLoss(name + ": missing '" + key + "'");
    if (!it->is_number_integer() || it->get<int64_t>() <= 0 || it->get<int64_t>() > 100000)
      return DataLoss(name + ": '" + key + "' must be an integer in 1..100000, got " + it->dump().substr(0, 40));
    (std::string(key) == "width" ? k.width : k.height) = static_cast<int>(it->get<int64_t>());
  }
  const auto it = j.find("intrinsic_matrix");
  if (it == j.end()) return DataLoss(name + ": missing 'intrinsic_matrix'");
  if (!it->is_array() || it->size() != 9)
    return DataLoss(name + ": 'intrinsic_matrix' must be an array of 9 numbers");
  double v[9];
  for (size_t i = 0; i < 9; ++i) {
    if (!(*it)[i].is_number()) return DataLoss(name + ": intrinsic_matrix[" + std::to_string(i) + "] is not a number");
    v[i] = (*it)[i].get<double>();
    if (!std::isfinite(v[i])) return DataLoss(name + ": intrinsic_matrix[" + std::to_string(i) + "] is not finite");
  }
  // Column-major: [fx 0 0, s fy 0, cx cy 1].
  if (v[1] != 0 || v[2] != 0 || v[5] != 0 || v[8] != 1)
    return DataLoss(name + ": intrinsic_matrix is not a pinhole matrix (column-major [fx 0 0 0 fy 0 cx cy 1])");
  if (v[3] != 0) return DataLoss(name + ": intrinsic_matrix has skew " + std::to_string(v[3]) + ", not supported");
  k.fx = v[0];
  k.fy = v[4];
  k.cx = v[6];
  k.cy = v[7];
  HOLO_RETURN_IF_ERROR(k.Check().WithContext(name));
  return k;
}

Status RedwoodImportOptions::Check() const { return CheckUnits(depth_units_per_metre); }

namespace {

// Sorted image file names (.png, .jpg, .jpeg) in `dir`.
Status ListImages(const std::string& dir, std::vector<std::string>* names) {
  names->clear();
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return NotFound(dir + ": directory not found");
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (!it->is_regular_file(ec)) continue;
    std::string ext = it->path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (ext != ".png" && ext != ".jpg" && ext != ".jpeg") continue;
    if (names->size() >= 1'000'000) return DataLoss(dir + ": more than 1000000 images");
    names->push_back(it->path().filename().string());
  }
  if (ec) return Unavailable(dir + ": cannot list: " + ec.message());
  std::sort(names->begin(), names->end());
  return OkStatus();
}

}  // namespace

StatusOr<ImportedScene> ImportRedwood(const std::string& dir, const RedwoodImportOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check().WithContext("RedwoodImportOptions"));
  Intrinsics k;
  std::string k_source = "RedwoodImportOptions.intrinsics";
  if (options.intrinsics) {
    k = *options.intrinsics;
    HOLO_RETURN_IF_ERROR(k.Check().WithContext(k_source));
  } else {
    k_source = dir + "/" + options.intrinsic_file;
    HOLO_ASSIGN_OR_RETURN(const std::string json, ReadTextFile(k_source));
    HOLO_ASSIGN_OR_RETURN(k, ParseOpen3dIntrinsicJson(json, k_source));
  }
  std::vector<std::string> color_names, depth_names;
  HOLO_RETURN_IF_ERROR(ListImages(dir + "/color", &color_names));
  HOLO_RETURN_IF_ERROR(ListImages(dir + "/depth", &depth_names));
  if (color_names.size() != depth_names.size())
    return DataLoss(dir + "/color: " + std::to_string(color_names.size()) + " images, but " + dir + "/depth has " +
                    std::to_string(depth_names.size()));
  if (depth_names.empty()) return DataLoss(dir + "/depth: no images");

  std::vector<Pose> poses;
  const bool has_poses = !options.trajectory_file.empty();
  if (has_poses) {
    const std::string traj_path = dir + "/" + options.trajectory_file;
    HOLO_ASSIGN_OR_RETURN(const std::string text, ReadTextFile(traj_path));
    HOLO_ASSIGN_OR_RETURN(poses, ParseRedwoodTrajectory(text, traj_path));
    if (poses.size() != depth_names.size())
      return DataLoss(traj_path + ": " + std::to_string(poses.size()) + " poses for " +
                      std::to_string(depth_names.size()) + " images in " + dir + "/depth");
  }
  HOLO_ASSIGN_OR_RETURN(const std::vector<size_t> selected, SelectFrames(options.frames, depth_names.size(), dir));

  ImportedScene scene;
  scene.rig.name = "redwood:" + std::filesystem::path(dir).filename().string();
  scene.has_poses = has_poses;
  for (size_t i = 0; i < selected.size(); ++i) {
    const size_t s = selected[i];
    RgbdFrame f;
    f.pod_id = static_cast<int>(i);
    // No capture times in this layout: frames are numbered at a nominal 30 fps.
    f.timestamp_us = static_cast<int64_t>(s) * 33333;
    const std::string depth_path = dir + "/depth/" + depth_names[s];
    const std::string color_path = dir + "/color/" + color_names[s];
    HOLO_RETURN_IF_ERROR(ReadDepth16(depth_path, &f.depth));
    HOLO_RETURN_IF_ERROR(CheckImageSize(f.depth, k.width, k.height, depth_path, k_source));
    HOLO_RETURN_IF_ERROR(ReadImageRgb8(color_path, &f.color));
    HOLO_RETURN_IF_ERROR(CheckImageSize(f.color, k.width, k.height, color_path, k_source));
    ConvertDepthToMm(&f.depth, options.depth_units_per_metre);
    const Pose pose = has_poses ? poses[s] : Pose::Identity();
    scene.rig.pods.push_back(MakePod(static_cast<int>(i), "redwood_" + std::filesystem::path(depth_names[s]).stem().string(), k, pose));
    scene.frames.frames.push_back(std::move(f));
    scene.source_files.push_back("depth/" + depth_names[s]);
  }
  HOLO_RETURN_IF_ERROR(scene.rig.Check().WithContext(dir));
  return scene;
}

// ---------------------------------------------------------------------------
// MemoryFrameSource

StatusOr<std::unique_ptr<MemoryFrameSource>> MemoryFrameSource::Create(Rig rig, std::vector<RgbdFrameSet> sets) {
  HOLO_RETURN_IF_ERROR(rig.Check().WithContext("rig"));
  const auto& pods = rig.pods;
  for (size_t s = 0; s < sets.size(); ++s) {
    const std::string at = "frame set " + std::to_string(s);
    if (sets[s].frames.size() != pods.size())
      return InvalidArgument(at + ": " + std::to_string(sets[s].frames.size()) + " frames for " +
                             std::to_string(pods.size()) + " pods");
    for (size_t k = 0; k < pods.size(); ++k) {
      const RgbdFrame& f = sets[s].frames[k];
      const std::string pod = at + " pod " + std::to_string(k);
      if (f.pod_id != static_cast<int>(k)) return InvalidArgument(pod + ": pod_id is " + std::to_string(f.pod_id));
      if (f.color.width() != pods[k].color.width || f.color.height() != pods[k].color.height)
        return InvalidArgument(pod + ": color size differs from the rig");
      if (f.depth.width() != pods[k].depth.width || f.depth.height() != pods[k].depth.height)
        return InvalidArgument(pod + ": depth size differs from the rig");
      if (!f.mask.empty() && (f.mask.width() != pods[k].depth.width || f.mask.height() != pods[k].depth.height))
        return InvalidArgument(pod + ": mask size differs from the rig's depth size");
    }
  }
  std::unique_ptr<MemoryFrameSource> src(new MemoryFrameSource());
  src->rig_ = std::move(rig);
  src->sets_ = std::move(sets);
  return src;
}

StatusOr<std::unique_ptr<MemoryFrameSource>> MemoryFrameSource::FromScene(ImportedScene scene) {
  std::vector<RgbdFrameSet> sets;
  sets.push_back(std::move(scene.frames));
  return Create(std::move(scene.rig), std::move(sets));
}

Status MemoryFrameSource::Next(RgbdFrameSet* out) {
  if (cursor_ >= num_frames())
    return OutOfRange("memory frame source: end (" + std::to_string(num_frames()) + " frame sets)");
  *out = sets_[static_cast<size_t>(cursor_++)];
  return OkStatus();
}

Status MemoryFrameSource::Seek(int64_t index) {
  if (index < 0 || index >= num_frames())
    return OutOfRange("memory frame source: seek to " + std::to_string(index) + " of " + std::to_string(num_frames()));
  cursor_ = index;
  return OkStatus();
}

}  // namespace holo
