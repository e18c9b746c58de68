#include "common/rig.h"

#include <cmath>
#include <iomanip>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "common/file_util.h"
#include "common/yaml_util.h"

namespace holo {

bool PodCalibration::IsRegistered() const {
  const bool same_k = depth.width == color.width && depth.height == color.height && depth.fx == color.fx &&
                      depth.fy == color.fy && depth.cx == color.cx && depth.cy == color.cy &&
                      depth.distortion == color.distortion;
  return same_k && color_from_depth.matrix().isApprox(Eigen::Matrix4f::Identity(), 1e-6f);
}

CameraModel PodCalibration::RightIrCamera() const {
  Pose left_from_right = Pose::Identity();
  left_from_right.translation() = Eigen::Vector3f(static_cast<float>(stereo.baseline_m), 0.0f, 0.0f);
  return {stereo.ir, world_from_depth * left_from_right};
}

Status StereoCalibration::Check() const {
  if (!enabled) return OkStatus();
  HOLO_RETURN_IF_ERROR(ir.Check().WithContext("ir"));
  if (ir.HasDistortion()) return InvalidArgument("ir.distortion must be zero: the IR pair is rectified");
  if (!(baseline_m >= 0.01 && baseline_m <= 1.0))
    return InvalidArgument("baseline_m must be in [0.01, 1], got " + FormatNumber(baseline_m));
  if (!(projector.position.allFinite() && projector.position.norm() <= 1.0f))
    return InvalidArgument("projector.position must be finite and within 1 m of the left IR camera");
  if (!(projector.dot_pitch_mrad >= 0.2 && projector.dot_pitch_mrad <= 50.0))
    return InvalidArgument("projector.dot_pitch_mrad must be in [0.2, 50], got " +
                           FormatNumber(projector.dot_pitch_mrad));
  if (!(projector.dot_density > 0.0 && projector.dot_density <= 1.0))
    return InvalidArgument("projector.dot_density must be in (0, 1], got " + FormatNumber(projector.dot_density));
  if (!(projector.power_at_1m > 0.0 && projector.power_at_1m <= 100.0))
    return InvalidArgument("projector.power_at_1m must be in (0, 100], got " + FormatNumber(projector.power_at_1m));
  return OkStatus();
}

Rig Rig::Scaled(double s) const {
  Rig out = *this;
  for (auto& pod : out.pods) {
    pod.depth = pod.depth.Scaled(s);
    pod.color = pod.color.Scaled(s);
    if (pod.stereo.enabled) pod.stereo.ir = pod.stereo.ir.Scaled(s);
  }
  return out;
}

Status Rig::Check() const {
  if (pods.empty()) return InvalidArgument("pods: a rig needs at least one pod");
  if (pods.size() > 64) return InvalidArgument("pods: at most 64 pods, got " + std::to_string(pods.size()));
  for (size_t i = 0; i < pods.size(); ++i) {
    const std::string at = "pods[" + std::to_string(i) + "]";
    if (pods[i].id != static_cast<int>(i))
      return InvalidArgument(at + ".id: pods must be numbered 0..N-1 in order, got " + std::to_string(pods[i].id));
    HOLO_RETURN_IF_ERROR(pods[i].depth.Check().WithContext(at + ".depth"));
    HOLO_RETURN_IF_ERROR(pods[i].color.Check().WithContext(at + ".color"));
    HOLO_RETURN_IF_ERROR(pods[i].stereo.Check().WithContext(at + ".stereo"));
  }
  return OkStatus();
}

namespace {

// Errors carry "key: message" (KeyError); the caller prefixes the source name.

std::string Repr(const YAML::Node& n) {
  if (!n.IsDefined() || n.IsNull()) return "(missing)";
  if (n.IsScalar()) return "'" + n.Scalar() + "'";
  YAML::Emitter e;
  e << YAML::Flow << n;
  return e.c_str();
}

Status GetDouble(const YAML::Node& parent, const std::string& field, const std::string& key, double* out,
                 bool required = true) {
  const YAML::Node n = parent[field];
  if (!n.IsDefined() || n.IsNull()) {
    if (!required) return OkStatus();
    return KeyError(key, "missing (a number is required)");
  }
  if (!n.IsScalar()) return KeyError(key, "must be a number, got " + Repr(n));
  double v;
  try {
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    return KeyError(key, "must be a number, got " + Repr(n));
  }
  if (!std::isfinite(v)) return KeyError(key, "must be finite, got " + Repr(n));
  *out = v;
  return OkStatus();
}

Status GetInt(const YAML::Node& parent, const std::string& field, const std::string& key, int* out) {
  const YAML::Node n = parent[field];
  if (!n.IsDefined() || n.IsNull()) return KeyError(key, "missing (an integer is required)");
  if (!n.IsScalar()) return KeyError(key, "must be an integer, got " + Repr(n));
  try {
    *out = n.as<int>();
  } catch (const YAML::Exception&) {
    return KeyError(key, "must be an integer, got " + Repr(n));
  }
  return OkStatus();
}

Status GetVector(const YAML::Node& parent, const std::string& field, const std::string& key, size_t size,
                 std::vector<double>* out) {
  const YAML::Node n = parent[field];
  if (!n.IsDefined() || n.IsNull()) return KeyError(key, "missing (a list of " + std::to_string(size) + " numbers)");
  if (!n.IsSequence() || n.size() != size)
    return KeyError(key, "must be a list of " + std::to_string(size) + " numbers, got " + Repr(n));
  out->clear();
  for (size_t i = 0; i < size; ++i) {
    double v;
    try {
      v = n[i].as<double>();
    } catch (const YAML::Exception&) {
      return KeyError(key + "[" + std::to_string(i) + "]", "must be a number, got " + Repr(n[i]));
    }
    if (!std::isfinite(v)) return KeyError(key + "[" + std::to_string(i) + "]", "must be finite");
    out->push_back(v);
  }
  return OkStatus();
}

Status ParseIntrinsics(const YAML::Node& n, const std::string& key, Intrinsics* k) {
  if (!n.IsDefined() || !n.IsMap()) return KeyError(key, "missing or not a map of width/height/fx/fy/cx/cy");
  HOLO_RETURN_IF_ERROR(GetInt(n, "width", key + ".width", &k->width));
  HOLO_RETURN_IF_ERROR(GetInt(n, "height", key + ".height", &k->height));
  HOLO_RETURN_IF_ERROR(GetDouble(n, "fx", key + ".fx", &k->fx));
  HOLO_RETURN_IF_ERROR(GetDouble(n, "fy", key + ".fy", &k->fy));
  HOLO_RETURN_IF_ERROR(GetDouble(n, "cx", key + ".cx", &k->cx));
  HOLO_RETURN_IF_ERROR(GetDouble(n, "cy", key + ".cy", &k->cy));
  if (n["distortion"].IsDefined() && !n["distortion"].IsNull()) {
    std::vector<double> d;
    HOLO_RETURN_IF_ERROR(GetVector(n, "distortion", key + ".distortion", 5, &d));
    for (int i = 0; i < 5; ++i) k->distortion[i] = d[i];
  }
  // Field-level checks, reported with the precise key.
  const Status s = k->Check();
  if (!s.ok()) {
    const std::string& m = s.message();
    const size_t sp = m.find(' ');
    const std::string field = m.substr(0, sp);
    return KeyError(key + "." + field, m.substr(sp + 1));
  }
  return OkStatus();
}

// A pose is either {translation: [x,y,z], quaternion_wxyz: [w,x,y,z]} or
// {eye: [x,y,z], target: [x,y,z], up: [x,y,z] (optional, default z)}.
Status ParsePose(const YAML::Node& n, const std::string& key, Pose* pose) {
  if (!n.IsDefined() || !n.IsMap()) return KeyError(key, "missing or not a map");
  std::vector<double> a, b, c;
  if (n["eye"].IsDefined()) {
    HOLO_RETURN_IF_ERROR(GetVector(n, "eye", key + ".eye", 3, &a));
    HOLO_RETURN_IF_ERROR(GetVector(n, "target", key + ".target", 3, &b));
    Eigen::Vector3f up = Eigen::Vector3f::UnitZ();
    if (n["up"].IsDefined()) {
      HOLO_RETURN_IF_ERROR(GetVector(n, "up", key + ".up", 3, &c));
      up = Eigen::Vector3f(c[0], c[1], c[2]);
      if (up.norm() < 1e-6f) return KeyError(key + ".up", "must not be zero");
    }
    const Eigen::Vector3f eye(a[0], a[1], a[2]), target(b[0], b[1], b[2]);
    if ((target - eye).norm() < 1e-6f) return KeyError(key + ".target", "must differ from eye");
    *pose = LookAt(eye, target, up);
    return OkStatus();
  }
  HOLO_RETURN_IF_ERROR(GetVector(n, "translation", key + ".translation", 3, &a));
  HOLO_RETURN_IF_ERROR(GetVector(n, "quaternion_wxyz", key + ".quaternion_wxyz", 4, &b));
  Eigen::Quaterniond q(b[0], b[1], b[2], b[3]);
  const double norm = q.norm();
  if (std::abs(norm - 1.0) > 1e-3)
    return KeyError(key + ".quaternion_wxyz", "must be a unit quaternion, got norm " + std::to_string(norm));
  q.normalize();
  *pose = Pose::Identity();
  pose->linear() = q.toRotationMatrix().cast<float>();
  pose->translation() = Eigen::Vector3f(a[0], a[1], a[2]);
  return OkStatus();
}

// Optional `stereo:` block of a pod; `depth` is the default IR intrinsics.
Status ParseStereo(const YAML::Node& n, const std::string& key, const Intrinsics& depth, StereoCalibration* st) {
  if (!n.IsMap()) return KeyError(key, "must be a map with baseline_m (and optionally ir, projector)");
  st->enabled = true;
  st->ir = depth;
  if (n["ir"].IsDefined()) HOLO_RETURN_IF_ERROR(ParseIntrinsics(n["ir"], key + ".ir", &st->ir));
  if (st->ir.HasDistortion()) return KeyError(key + ".ir.distortion", "must be zero: the IR pair is rectified");
  HOLO_RETURN_IF_ERROR(GetDouble(n, "baseline_m", key + ".baseline_m", &st->baseline_m));
  const YAML::Node pj = n["projector"];
  if (pj.IsDefined() && !pj.IsNull()) {
    if (!pj.IsMap()) return KeyError(key + ".projector", "must be a map");
    if (pj["position"].IsDefined()) {
      std::vector<double> p;
      HOLO_RETURN_IF_ERROR(GetVector(pj, "position", key + ".projector.position", 3, &p));
      st->projector.position = Eigen::Vector3f(p[0], p[1], p[2]);
    }
    HOLO_RETURN_IF_ERROR(
        GetDouble(pj, "dot_pitch_mrad", key + ".projector.dot_pitch_mrad", &st->projector.dot_pitch_mrad, false));
    HOLO_RETURN_IF_ERROR(
        GetDouble(pj, "dot_density", key + ".projector.dot_density", &st->projector.dot_density, false));
    HOLO_RETURN_IF_ERROR(
        GetDouble(pj, "power_at_1m", key + ".projector.power_at_1m", &st->projector.power_at_1m, false));
  }
  const Status s = st->Check();
  if (!s.ok()) {
    const std::string& m = s.message();
    const size_t sp = m.find(' ');
    return KeyError(key + "." + m.substr(0, sp), m.substr(sp + 1));
  }
  return OkStatus();
}

}  // namespace

StatusOr<Rig> ParseRigYaml(const std::string& yaml_text, const std::string& source_name) {
  HOLO_ASSIGN_OR_RETURN(YAML::Node root, LoadYaml(yaml_text, source_name));
  auto fail = [&](const Status& s) { return s.WithContext(source_name); };
  if (!root.IsMap()) return InvalidArgument(source_name + ": top level must be a map with 'name' and 'pods'");
  Rig rig;
  if (root["name"].IsDefined() && root["name"].IsScalar()) rig.name = root["name"].Scalar();
  const YAML::Node pods = root["pods"];
  if (!pods.IsDefined() || !pods.IsSequence() || pods.size() == 0)
    return fail(KeyError("pods", "missing or not a non-empty list"));
  if (pods.size() > 64) return fail(KeyError("pods", "at most 64 pods, got " + std::to_string(pods.size())));
  for (size_t i = 0; i < pods.size(); ++i) {
    const std::string key = "pods[" + std::to_string(i) + "]";
    const YAML::Node p = pods[i];
    if (!p.IsMap()) return fail(KeyError(key, "must be a map"));
    PodCalibration pod;
    pod.id = static_cast<int>(i);
    if (p["id"].IsDefined()) {
      Status s = GetInt(p, "id", key + ".id", &pod.id);
      if (!s.ok()) return fail(s);
      if (pod.id != static_cast<int>(i))
        return fail(KeyError(key + ".id", "pods must be numbered 0..N-1 in order, got " + std::to_string(pod.id)));
    }
    pod.name = p["name"].IsDefined() && p["name"].IsScalar() ? p["name"].Scalar() : "pod" + std::to_string(i);
    Status s = ParseIntrinsics(p["depth"], key + ".depth", &pod.depth);
    if (!s.ok()) return fail(s);
    if (p["color"].IsDefined()) {
      s = ParseIntrinsics(p["color"], key + ".color", &pod.color);
      if (!s.ok()) return fail(s);
    } else {
      pod.color = pod.depth;
    }
    if (p["color_from_depth"].IsDefined()) {
      s = ParsePose(p["color_from_depth"], key + ".color_from_depth", &pod.color_from_depth);
      if (!s.ok()) return fail(s);
    }
    s = ParsePose(p["world_from_depth"], key + ".world_from_depth", &pod.world_from_depth);
    if (!s.ok()) return fail(s);
    if (p["stereo"].IsDefined() && !p["stereo"].IsNull()) {
      s = ParseStereo(p["stereo"], key + ".stereo", pod.depth, &pod.stereo);
      if (!s.ok()) return fail(s);
    }
    rig.pods.push_back(pod);
  }
  return rig;
}

StatusOr<Rig> LoadRig(const std::string& path) {
  HOLO_ASSIGN_OR_RETURN(std::string text, ReadFileToString(path));
  return ParseRigYaml(text, path);
}

namespace {
void EmitIntrinsics(std::ostringstream& o, const char* name, const Intrinsics& k) {
  o << "    " << name << ": {width: " << k.width << ", height: " << k.height << ", fx: " << k.fx
    << ", fy: " << k.fy << ", cx: " << k.cx << ", cy: " << k.cy << ", distortion: [" << k.distortion[0] << ", "
    << k.distortion[1] << ", " << k.distortion[2] << ", " << k.distortion[3] << ", " << k.distortion[4] << "]}\n";
}
void EmitPose(std::ostringstream& o, const char* name, const Pose& p) {
  const Eigen::Quaternionf q(p.linear());
  const Eigen::Vector3f t = p.translation();
  o << "    " << name << ": {translation: [" << t.x() << ", " << t.y() << ", " << t.z() << "], quaternion_wxyz: ["
    << q.w() << ", " << q.x() << ", " << q.y() << ", " << q.z() << "]}\n";
}
}  // namespace

std::string RigToYaml(const Rig& rig) {
  std::ostringstream o;
  o << std::setprecision(9);
  o << "name: " << (rig.name.empty() ? "rig" : rig.name) << "\npods:\n";
  for (const auto& pod : rig.pods) {
    o << "  - id: " << pod.id << "\n    name: " << pod.name << "\n";
    EmitIntrinsics(o, "depth", pod.depth);
    EmitIntrinsics(o, "color", pod.color);
    EmitPose(o, "color_from_depth", pod.color_from_depth);
    EmitPose(o, "world_from_depth", pod.world_from_depth);
    if (pod.stereo.enabled) {
      const StereoCalibration& st = pod.stereo;
      const Eigen::Vector3f& pp = st.projector.position;
      o << "    stereo:\n      baseline_m: " << st.baseline_m << "\n  ";
      EmitIntrinsics(o, "ir", st.ir);
      o << "      projector: {position: [" << pp.x() << ", " << pp.y() << ", " << pp.z()
        << "], dot_pitch_mrad: " << st.projector.dot_pitch_mrad << ", dot_density: " << st.projector.dot_density
        << ", power_at_1m: " << st.projector.power_at_1m << "}\n";
    }
  }
  return o.str();
}

Status SaveRig(const std::string& path, const Rig& rig) { return WriteStringToFile(path, RigToYaml(rig)); }

std::string ShippedRigPath(const std::string& name) {
  return std::string(HOLO_SOURCE_DIR) + "/config/rigs/" + name + ".yaml";
}

}  // namespace holo
