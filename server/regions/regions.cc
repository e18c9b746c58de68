#include "server/regions/regions.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <yaml-cpp/yaml.h>

#include "common/file_util.h"
#include "common/yaml_util.h"

namespace holo::regions {
namespace {

Status GetFloat(const YAML::Node& map, const std::string& key, const std::string& where, float* out) {
  double v = *out;
  HOLO_RETURN_IF_ERROR(GetYamlNumber(map, key, where, &v));
  if (std::abs(v) > 1e6) return KeyError(where + key, "must be a finite number, got " + map[key].Scalar());
  *out = static_cast<float>(v);
  return OkStatus();
}

Status GetInt(const YAML::Node& map, const std::string& key, const std::string& where, int* out) {
  const YAML::Node n = map[key];
  if (!n.IsDefined()) return OkStatus();
  try {
    if (!n.IsScalar()) throw YAML::Exception(YAML::Mark(), "");
    *out = n.as<int>();
  } catch (const YAML::Exception&) {
    return KeyError(where + key, "must be a whole number, got '" + (n.IsScalar() ? n.Scalar() : std::string("(not a scalar)")) + "'");
  }
  return OkStatus();
}

Status GetVec3(const YAML::Node& map, const std::string& key, const std::string& where, Eigen::Vector3f* out) {
  const YAML::Node n = map[key];
  if (!n.IsDefined()) return KeyError(where + key, "missing (a list of 3 numbers, metres)");
  if (!n.IsSequence() || n.size() != 3) return KeyError(where + key, "must be a list of 3 numbers [x, y, z], metres");
  for (size_t i = 0; i < 3; ++i) {
    double v = 0;
    try {
      if (!n[i].IsScalar()) throw YAML::Exception(YAML::Mark(), "");
      v = n[i].as<double>();
    } catch (const YAML::Exception&) {
      return KeyError(where + key + "[" + std::to_string(i) + "]", "must be a number");
    }
    if (!std::isfinite(v) || std::abs(v) > 1000) return KeyError(where + key + "[" + std::to_string(i) + "]", "must be within ±1000 m");
    (*out)[static_cast<int>(i)] = static_cast<float>(v);
  }
  return OkStatus();
}

std::string Num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

}  // namespace

bool RegionSpec::Contains(const Eigen::Vector3f& p) const {
  if (shape == protocol::RegionShape::kSphere) return (p - min).squaredNorm() <= radius * radius;
  return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
}
Eigen::Vector3f RegionSpec::BoundsMin() const {
  return shape == protocol::RegionShape::kSphere ? Eigen::Vector3f(min.array() - radius) : min;
}
Eigen::Vector3f RegionSpec::BoundsMax() const {
  return shape == protocol::RegionShape::kSphere ? Eigen::Vector3f(min.array() + radius) : max;
}

Status RegionsConfig::Check() const {
  if (!(cell_m >= 0.002f && cell_m <= 1.0f)) return KeyError("cell_mm", "must be 2..1000, got " + Num(cell_m * 1e3));
  if (min_points_per_cell < 1 || min_points_per_cell > 1000)
    return KeyError("min_points_per_cell", "must be 1..1000, got " + std::to_string(min_points_per_cell));
  if (enter_frames < 1 || enter_frames > 300) return KeyError("enter_frames", "must be 1..300, got " + std::to_string(enter_frames));
  if (exit_frames < 1 || exit_frames > 300) return KeyError("exit_frames", "must be 1..300, got " + std::to_string(exit_frames));
  if (regions.empty()) return KeyError("regions", "must list at least one region");
  if (regions.size() > protocol::kMaxRegions)
    return KeyError("regions", std::to_string(regions.size()) + " regions, at most " + std::to_string(protocol::kMaxRegions));
  std::set<std::string> names;
  for (size_t i = 0; i < regions.size(); ++i) {
    const RegionSpec& r = regions[i];
    const std::string at = "regions[" + std::to_string(i) + "].";
    if (r.name.empty() || r.name.size() > protocol::kMaxRegionName)
      return KeyError(at + "name", "must be 1.." + std::to_string(protocol::kMaxRegionName) + " bytes");
    for (char c : r.name)
      if (static_cast<unsigned char>(c) < 0x20) return KeyError(at + "name", "must not hold control characters");
    if (!names.insert(r.name).second) return KeyError(at + "name", "'" + r.name + "' is used twice");
    if (r.shape == protocol::RegionShape::kBox) {
      for (int k = 0; k < 3; ++k)
        if (!(r.min[k] < r.max[k])) return KeyError(at + "box.max", "must exceed min on every axis");
      // Cells per region are sorted per frame: a region must not be absurdly large for its cell.
      const Eigen::Vector3f ext = r.max - r.min;
      if ((ext.array() / cell_m).maxCoeff() > 1e5f) return KeyError(at + "box", "more than 100000 cells along an axis");
    } else {
      if (!(r.radius > 0 && r.radius <= 100)) return KeyError(at + "sphere.radius", "must be in (0, 100] m, got " + Num(r.radius));
    }
    if (!(r.enter_litres > 0)) return KeyError(at + "enter_litres", "must be > 0, got " + Num(r.enter_litres));
    if (!(r.exit_litres >= 0 && r.exit_litres < r.enter_litres))
      return KeyError(at + "exit_litres", "must be >= 0 and below enter_litres (" + Num(r.enter_litres) + "), got " + Num(r.exit_litres));
  }
  return OkStatus();
}

StatusOr<RegionsConfig> ParseRegionsConfig(const std::string& text, const std::string& source) {
  HOLO_ASSIGN_OR_RETURN(YAML::Node root, LoadYaml(text, source));
  auto parse = [&]() -> StatusOr<RegionsConfig> {
    if (!root.IsMap()) return InvalidArgument("expected a map with a 'regions' list at the top level");
    HOLO_RETURN_IF_ERROR(CheckYamlKeys(root, {"cell_mm", "min_points_per_cell", "enter_litres", "exit_litres",
                                              "enter_frames", "exit_frames", "regions"}, ""));
    RegionsConfig c;
    float cell_mm = c.cell_m * 1e3f;
    HOLO_RETURN_IF_ERROR(GetFloat(root, "cell_mm", "", &cell_mm));
    c.cell_m = cell_mm * 1e-3f;
    HOLO_RETURN_IF_ERROR(GetInt(root, "min_points_per_cell", "", &c.min_points_per_cell));
    HOLO_RETURN_IF_ERROR(GetFloat(root, "enter_litres", "", &c.enter_litres));
    HOLO_RETURN_IF_ERROR(GetFloat(root, "exit_litres", "", &c.exit_litres));
    HOLO_RETURN_IF_ERROR(GetInt(root, "enter_frames", "", &c.enter_frames));
    HOLO_RETURN_IF_ERROR(GetInt(root, "exit_frames", "", &c.exit_frames));
    const YAML::Node list = root["regions"];
    if (!list.IsDefined()) return KeyError("regions", "missing (a list of regions)");
    if (!list.IsSequence()) return KeyError("regions", "must be a list");
    if (list.size() > protocol::kMaxRegions)
      return KeyError("regions", std::to_string(list.size()) + " regions, at most " + std::to_string(protocol::kMaxRegions));
    for (size_t i = 0; i < list.size(); ++i) {
      const YAML::Node n = list[i];
      const std::string at = "regions[" + std::to_string(i) + "].";
      if (!n.IsMap()) return KeyError(at.substr(0, at.size() - 1), "must be a map (name, box or sphere)");
      HOLO_RETURN_IF_ERROR(CheckYamlKeys(n, {"name", "box", "sphere", "enter_litres", "exit_litres"}, at));
      RegionSpec r;
      if (!n["name"].IsDefined()) return KeyError(at + "name", "missing");
      HOLO_RETURN_IF_ERROR(GetYamlString(n, "name", at, &r.name));
      const bool box = n["box"].IsDefined(), sphere = n["sphere"].IsDefined();
      if (box == sphere) return KeyError(at.substr(0, at.size() - 1), "needs exactly one of 'box' or 'sphere'");
      if (box) {
        const YAML::Node b = n["box"];
        if (!b.IsMap()) return KeyError(at + "box", "must be a map {min: [x, y, z], max: [x, y, z]}");
        HOLO_RETURN_IF_ERROR(CheckYamlKeys(b, {"min", "max"}, at + "box."));
        r.shape = protocol::RegionShape::kBox;
        HOLO_RETURN_IF_ERROR(GetVec3(b, "min", at + "box.", &r.min));
        HOLO_RETURN_IF_ERROR(GetVec3(b, "max", at + "box.", &r.max));
      } else {
        const YAML::Node s = n["sphere"];
        if (!s.IsMap()) return KeyError(at + "sphere", "must be a map {center: [x, y, z], radius: r}");
        HOLO_RETURN_IF_ERROR(CheckYamlKeys(s, {"center", "radius"}, at + "sphere."));
        r.shape = protocol::RegionShape::kSphere;
        HOLO_RETURN_IF_ERROR(GetVec3(s, "center", at + "sphere.", &r.min));
        if (!s["radius"].IsDefined()) return KeyError(at + "sphere.radius", "missing");
        HOLO_RETURN_IF_ERROR(GetFloat(s, "radius", at + "sphere.", &r.radius));
        r.max = r.min;
      }
      r.enter_litres = c.enter_litres;
      r.exit_litres = c.exit_litres;
      HOLO_RETURN_IF_ERROR(GetFloat(n, "enter_litres", at, &r.enter_litres));
      HOLO_RETURN_IF_ERROR(GetFloat(n, "exit_litres", at, &r.exit_litres));
      c.regions.push_back(std::move(r));
    }
    HOLO_RETURN_IF_ERROR(c.Check());
    return c;
  };
  auto c = parse();
  if (!c.ok()) return c.status().WithContext(source);
  return c;
}

StatusOr<RegionsConfig> LoadRegionsConfig(const std::string& path) {
  HOLO_ASSIGN_OR_RETURN(std::string text, ReadFileToString(path));
  return ParseRegionsConfig(text, path);
}

float OccupiedLitres(const RegionSpec& region, std::span<const Eigen::Vector3f> points, float cell_m,
                     int min_points_per_cell, std::vector<uint64_t>* scratch) {
  const Eigen::Vector3f lo = region.BoundsMin(), hi = region.BoundsMax();
  const float inv = 1.0f / cell_m;
  // Cell keys: 21 bits per axis (Check keeps a region under 100000 cells a side).
  scratch->clear();
  for (const Eigen::Vector3f& p : points) {
    if ((p.array() < lo.array()).any() || (p.array() > hi.array()).any()) continue;
    if (!region.Contains(p)) continue;
    const Eigen::Vector3f c = (p - lo) * inv;
    const auto x = static_cast<uint64_t>(c.x()), y = static_cast<uint64_t>(c.y()), z = static_cast<uint64_t>(c.z());
    scratch->push_back((x << 42) | (y << 21) | z);
  }
  std::sort(scratch->begin(), scratch->end());
  size_t cells = 0;
  for (size_t i = 0; i < scratch->size();) {
    size_t j = i + 1;
    while (j < scratch->size() && (*scratch)[j] == (*scratch)[i]) ++j;
    if (static_cast<int>(j - i) >= min_points_per_cell) ++cells;
    i = j;
  }
  return static_cast<float>(static_cast<double>(cells) * cell_m * cell_m * cell_m * 1e3);
}

RegionTracker::RegionTracker(RegionsConfig config) : config_(std::move(config)) {
  const Status s = config_.Check();
  HOLO_CHECK_MSG(s.ok(), s.message().c_str());
  tracks_.resize(config_.regions.size());
  report_.regions.resize(config_.regions.size());
  for (size_t i = 0; i < config_.regions.size(); ++i) {
    const RegionSpec& r = config_.regions[i];
    protocol::RegionReport& g = report_.regions[i];
    g.name = r.name;
    g.shape = r.shape;
    g.a = {r.min.x(), r.min.y(), r.min.z()};
    if (r.shape == protocol::RegionShape::kBox)
      g.b = {r.max.x(), r.max.y(), r.max.z()};
    else
      g.b = {r.radius, 0, 0};
  }
}

const protocol::Regions& RegionTracker::Update(int64_t frame_index, std::span<const Eigen::Vector3f> points) {
  report_.frame_index = std::max<int64_t>(0, frame_index);
  for (size_t i = 0; i < config_.regions.size(); ++i) {
    const RegionSpec& r = config_.regions[i];
    Track& t = tracks_[i];
    protocol::RegionReport& g = report_.regions[i];
    const float v = OccupiedLitres(r, points, config_.cell_m, config_.min_points_per_cell, &scratch_);
    g.occupied_litres = v;
    if (!t.occupied) {
      t.run = v >= r.enter_litres ? t.run + 1 : 0;
      if (t.run >= config_.enter_frames) {
        t.occupied = true;
        t.run = 0;
        g.state = protocol::RegionState::kEnter;
        ++events_;
      } else {
        g.state = protocol::RegionState::kEmpty;
      }
    } else {
      t.run = v < r.exit_litres ? t.run + 1 : 0;
      if (t.run >= config_.exit_frames) {
        t.occupied = false;
        t.run = 0;
        g.state = protocol::RegionState::kLeave;
        ++events_;
      } else {
        g.state = protocol::RegionState::kStay;
      }
    }
  }
  return report_;
}

}  // namespace holo::regions
