#include "client/net/call_config.h"

#include <cmath>
#include <numbers>

#include <yaml-cpp/yaml.h>

#include "common/file_util.h"
#include "common/yaml_util.h"

namespace holo::net {
namespace {

Status GetFloat(const YAML::Node& m, const std::string& key, const std::string& where, float lo, float hi, float* out) {
  if (!m[key].IsDefined()) return OkStatus();
  double v = 0;
  HOLO_RETURN_IF_ERROR(GetYamlNumber(m, key, where, &v));
  if (v < lo || v > hi)
    return KeyError(where + key, "must be in " + std::to_string(lo) + ".." + std::to_string(hi));
  *out = static_cast<float>(v);
  return OkStatus();
}

Status ParseAddress(const std::string& spec, const std::string& key, std::string* host, uint16_t* port) {
  const size_t colon = spec.rfind(':');
  if (spec.empty()) return KeyError(key, "must be set (HOST:PORT)");
  if (colon == std::string::npos || colon == 0) return KeyError(key, "'" + spec + "': expected HOST:PORT");
  std::string h = spec.substr(0, colon);
  const std::string p = spec.substr(colon + 1);
  if (h.size() >= 2 && h.front() == '[' && h.back() == ']') h = h.substr(1, h.size() - 2);
  if (p.empty() || p.size() > 5 || p.find_first_not_of("0123456789") != std::string::npos || std::stol(p) < 1 ||
      std::stol(p) > 65535)
    return KeyError(key, "'" + spec + "': port must be 1..65535");
  *host = h;
  *port = static_cast<uint16_t>(std::stol(p));
  return OkStatus();
}

Status ParseSite(const YAML::Node& n, const std::string& where, bool local, CallSite* site) {
  if (!n.IsDefined()) return KeyError(where, "missing");
  if (!n.IsMap()) return KeyError(where, "must be a map (name, address, tokens)");
  HOLO_RETURN_IF_ERROR(CheckYamlKeys(n, {"name", "address", "publisher_token", "viewer_token"}, where + "."));
  HOLO_RETURN_IF_ERROR(GetYamlString(n, "name", where + ".", &site->name));
  std::string address;
  HOLO_RETURN_IF_ERROR(GetYamlString(n, "address", where + ".", &address));
  HOLO_RETURN_IF_ERROR(ParseAddress(address, where + ".address", &site->host, &site->port));
  HOLO_RETURN_IF_ERROR(GetYamlString(n, "publisher_token", where + ".", &site->publisher_token));
  HOLO_RETURN_IF_ERROR(GetYamlString(n, "viewer_token", where + ".", &site->viewer_token));
  if (local && site->publisher_token.empty())
    return KeyError(where + ".publisher_token", "must be set (the own audio+pose is published to the local site)");
  if (!local && site->viewer_token.empty())
    return KeyError(where + ".viewer_token", "must be set (to watch the remote site)");
  if (site->publisher_token.size() > 256 || site->viewer_token.size() > 256)
    return KeyError(where, "tokens are at most 256 bytes");
  if (site->name.empty()) site->name = local ? "local" : "remote";
  return OkStatus();
}

}  // namespace

StatusOr<CallConfig> ParseCallConfig(const std::string& yaml_text, const std::string& source) {
  HOLO_ASSIGN_OR_RETURN(YAML::Node root, LoadYaml(yaml_text, source));
  CallConfig c;
  auto parse = [&]() -> Status {
    if (!root.IsMap()) return InvalidArgument("expected a map with local, remote, room");
    HOLO_RETURN_IF_ERROR(CheckYamlKeys(root, {"local", "remote", "room", "tls"}, ""));
    HOLO_RETURN_IF_ERROR(ParseSite(root["local"], "local", true, &c.local));
    HOLO_RETURN_IF_ERROR(ParseSite(root["remote"], "remote", false, &c.remote));
    if (c.local.host == c.remote.host && c.local.port == c.remote.port)
      return KeyError("remote.address", "is the local site's address");
    const YAML::Node room = root["room"];
    if (!room.IsDefined())
      return KeyError("room", "missing (preset: face-to-face, or yaw_deg/pitch_deg/roll_deg + translation_m)");
    if (!room.IsMap()) return KeyError("room", "must be a map");
    HOLO_RETURN_IF_ERROR(
        CheckYamlKeys(room, {"preset", "gap_m", "yaw_deg", "pitch_deg", "roll_deg", "translation_m"}, "room."));
    std::string preset;
    HOLO_RETURN_IF_ERROR(GetYamlString(room, "preset", "room.", &preset));
    if (!preset.empty()) {
      if (preset != "face-to-face") return KeyError("room.preset", "'" + preset + "': known presets: face-to-face");
      for (const char* k : {"yaw_deg", "pitch_deg", "roll_deg", "translation_m"})
        if (room[k].IsDefined()) return KeyError(std::string("room.") + k, "not with a preset");
      float gap = 0;
      HOLO_RETURN_IF_ERROR(GetFloat(room, "gap_m", "room.", 0.0f, 100.0f, &gap));
      c.room = audio::FaceToFaceLink(gap);
    } else {
      if (room["gap_m"].IsDefined()) return KeyError("room.gap_m", "only with preset: face-to-face");
      float yaw = 0, pitch = 0, roll = 0;
      HOLO_RETURN_IF_ERROR(GetFloat(room, "yaw_deg", "room.", -360.0f, 360.0f, &yaw));
      HOLO_RETURN_IF_ERROR(GetFloat(room, "pitch_deg", "room.", -90.0f, 90.0f, &pitch));
      HOLO_RETURN_IF_ERROR(GetFloat(room, "roll_deg", "room.", -360.0f, 360.0f, &roll));
      Eigen::Vector3f t = Eigen::Vector3f::Zero();
      const YAML::Node tn = room["translation_m"];
      if (tn.IsDefined()) {
        if (!tn.IsSequence() || tn.size() != 3) return KeyError("room.translation_m", "must be [x, y, z] in metres");
        for (int i = 0; i < 3; ++i) {
          double v = 0;
          try {
            v = tn[i].as<double>();
          } catch (const YAML::Exception&) {
            return KeyError("room.translation_m", "must be [x, y, z] in metres");
          }
          if (!std::isfinite(v) || std::abs(v) > 1000)
            return KeyError("room.translation_m", "|value| must be <= 1000 m");
          t[i] = static_cast<float>(v);
        }
      }
      // Same convention as audio/room.h: R = Rz(yaw) · Ry(−pitch) · Rx(roll).
      const float d = std::numbers::pi_v<float> / 180.0f;
      c.room.local_from_remote.linear() = (Eigen::AngleAxisf(yaw * d, Eigen::Vector3f::UnitZ()) *
                                           Eigen::AngleAxisf(-pitch * d, Eigen::Vector3f::UnitY()) *
                                           Eigen::AngleAxisf(roll * d, Eigen::Vector3f::UnitX()))
                                              .toRotationMatrix();
      c.room.local_from_remote.translation() = t;
    }
    const YAML::Node tls = root["tls"];
    if (tls.IsDefined()) {
      if (!tls.IsMap()) return KeyError("tls", "must be a map (enabled, ca)");
      HOLO_RETURN_IF_ERROR(CheckYamlKeys(tls, {"enabled", "ca"}, "tls."));
      HOLO_RETURN_IF_ERROR(GetYamlBool(tls, "enabled", "tls.", &c.tls));
      HOLO_RETURN_IF_ERROR(GetYamlString(tls, "ca", "tls.", &c.tls_ca_file));
    }
    return OkStatus();
  };
  Status s = parse();
  if (!s.ok()) return s.WithContext(source);
  return c;
}

StatusOr<CallConfig> LoadCallConfig(const std::string& path) {
  HOLO_ASSIGN_OR_RETURN(std::string text, ReadFileToString(path));
  HOLO_ASSIGN_OR_RETURN(CallConfig c, ParseCallConfig(text, path));
  c.tls_ca_file = PathNextTo(path, c.tls_ca_file);
  return c;
}

}  // namespace holo::net
