// Small helpers shared by the YAML parsers of config files (rig, site server,
// call). Errors are InvalidArgument "key: message", naming the key with its
// path ("room.yaw_deg: ..."); callers prefix the file name with
// Status::WithContext(source). Safe on untrusted text: YAML errors become
// Status, never exceptions.
#pragma once

#include <set>
#include <string>

#include <yaml-cpp/yaml.h>

#include "common/status.h"

namespace holo {

// InvalidArgument("<key>: <message>").
Status KeyError(const std::string& key, const std::string& message);

// Parses `text`; a syntax error is "<source>: not valid YAML: <yaml-cpp's
// message>". Empty text gives a null node.
StatusOr<YAML::Node> LoadYaml(const std::string& text, const std::string& source);

// Fails on the first key of `map` not in `known`:
// "<where><key>: unknown key (known: a, b, c)". `where` is the path of the map
// with a trailing dot ("tls.") or empty at the top level. A key that is a
// list or a map is an error too.
Status CheckYamlKeys(const YAML::Node& map, const std::set<std::string>& known, const std::string& where);

// Reads the optional scalar map[key] into *out ("<where><key>: must be a
// string" when it is not a scalar); an absent key leaves *out unchanged.
Status GetYamlString(const YAML::Node& map, const std::string& key, const std::string& where, std::string* out);

// Reads the optional boolean map[key] into *out ("<where><key>: must be true
// or false"); an absent key leaves *out unchanged.
Status GetYamlBool(const YAML::Node& map, const std::string& key, const std::string& where, bool* out);

// Reads the optional number map[key] into *out ("<where><key>: must be a
// number, got '…'", or "must be a finite number, got …" for .nan / .inf); an
// absent key leaves *out unchanged. Ranges are the caller's.
Status GetYamlNumber(const YAML::Node& map, const std::string& key, const std::string& where, double* out);

}  // namespace holo
