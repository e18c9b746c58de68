#pragma once

#include <string>

#include "common/status.h"

namespace holo {

// Reads a whole file. NotFound naming the path if it cannot be opened.
StatusOr<std::string> ReadFileToString(const std::string& path);
// Writes atomically enough for our use: to `path`.tmp, then rename.
Status WriteStringToFile(const std::string& path, const std::string& data);
// Creates a directory and its parents; OK if it exists.
Status MakeDirs(const std::string& path);
bool FileExists(const std::string& path);
// `path` taken relative to the folder of the file `base` (a config naming a
// certificate, say): "sites/call.yaml" + "ca.pem" → "sites/ca.pem". An empty
// or absolute `path`, or a `base` without a folder, gives `path` unchanged.
std::string PathNextTo(const std::string& base, const std::string& path);

}  // namespace holo
