#include "common/yaml_util.h"

#include <cmath>

namespace holo {

Status KeyError(const std::string& key, const std::string& message) { return InvalidArgument(key + ": " + message); }

StatusOr<YAML::Node> LoadYaml(const std::string& text, const std::string& source) {
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    return InvalidArgument(source + ": not valid YAML: " + e.what());
  }
}

Status CheckYamlKeys(const YAML::Node& map, const std::set<std::string>& known, const std::string& where) {
  for (const auto& kv : map) {
    if (!kv.first.IsScalar())  // as<std::string>() would throw
      return KeyError(where.empty() ? "(top level)" : where.substr(0, where.size() - 1),
                      "keys must be names, not lists or maps");
    const std::string k = kv.first.Scalar();
    if (!known.count(k)) {
      std::string list;
      for (const auto& s : known) list += (list.empty() ? "" : ", ") + s;
      return KeyError(where + k, "unknown key (known: " + list + ")");
    }
  }
  return OkStatus();
}

Status GetYamlString(const YAML::Node& map, const std::string& key, const std::string& where, std::string* out) {
  const YAML::Node n = map[key];
  if (!n.IsDefined()) return OkStatus();
  if (!n.IsScalar()) return KeyError(where + key, "must be a string");
  *out = n.Scalar();
  return OkStatus();
}

Status GetYamlBool(const YAML::Node& map, const std::string& key, const std::string& where, bool* out) {
  const YAML::Node n = map[key];
  if (!n.IsDefined()) return OkStatus();
  try {
    *out = n.as<bool>();
  } catch (const YAML::Exception&) {
    return KeyError(where + key, "must be true or false");
  }
  return OkStatus();
}

Status GetYamlNumber(const YAML::Node& map, const std::string& key, const std::string& where, double* out) {
  const YAML::Node n = map[key];
  if (!n.IsDefined()) return OkStatus();
  double v = 0;
  try {
    if (!n.IsScalar()) throw YAML::Exception(YAML::Mark(), "");
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    return KeyError(where + key,
                    "must be a number, got '" + (n.IsScalar() ? n.Scalar() : std::string("(not a scalar)")) + "'");
  }
  if (!std::isfinite(v)) return KeyError(where + key, "must be a finite number, got " + n.Scalar());
  *out = v;
  return OkStatus();
}

}  // namespace holo
