#include "net/server_config.h"

#include <cmath>

#include <yaml-cpp/yaml.h>

#include "common/file_util.h"
#include "common/yaml_util.h"

namespace holo::net {
namespace {

template <typename T>
Status GetNumber(const YAML::Node& root, const std::string& key, T* out) {
  const YAML::Node n = root[key];
  if (!n.IsDefined()) return OkStatus();
  try {
    if (!n.IsScalar()) throw YAML::Exception(YAML::Mark(), "");
    *out = n.as<T>();
  } catch (const YAML::Exception&) {
    return KeyError(key,
                    "must be a number, got '" + (n.IsScalar() ? n.Scalar() : std::string("(not a scalar)")) + "'");
  }
  return OkStatus();
}

}  // namespace

Status ParseHostPort(const std::string& spec, std::string* host, uint16_t* port) {
  const size_t colon = spec.rfind(':');
  if (colon == std::string::npos) return InvalidArgument("'" + spec + "': expected HOST:PORT");
  std::string h = spec.substr(0, colon);
  const std::string p = spec.substr(colon + 1);
  if (h.size() >= 2 && h.front() == '[' && h.back() == ']') h = h.substr(1, h.size() - 2);
  if (h.empty()) h = "0.0.0.0";
  if (p.empty() || p.size() > 5 || p.find_first_not_of("0123456789") != std::string::npos)
    return InvalidArgument("'" + spec + "': port must be a number 0..65535");
  const long v = std::stol(p);
  if (v > 65535) return InvalidArgument("'" + spec + "': port must be a number 0..65535");
  *host = h;
  *port = static_cast<uint16_t>(v);
  return OkStatus();
}

Status ServerConfig::Check() const {
  if (name.empty() || name.size() > 1024) return KeyError("name", "1..1024 bytes");
  if (host.empty()) return KeyError("listen", "host must not be empty");
  if (publisher_token.empty() || publisher_token.size() > 256)
    return KeyError("publisher_token", "must be set, 1..256 bytes");
  if (viewer_token.empty() || viewer_token.size() > 256)
    return KeyError("viewer_token", "must be set, 1..256 bytes");
  if (publisher_token == viewer_token)
    return KeyError("publisher_token", "must differ from viewer_token (a viewer could publish otherwise)");
  if (max_viewers < 1 || max_viewers > 100000) return KeyError("max_viewers", "1..100000");
  if (max_publishers < 0 || max_publishers > 1000) return KeyError("max_publishers", "0..1000");
  if (max_pending < 1 || max_pending > 100000) return KeyError("max_pending", "1..100000");
  if (max_message_bytes < 1024 || max_message_bytes > (64u << 20))
    return KeyError("max_message_bytes", "1024..67108864 (the protocol's hard limit)");
  auto finite_pos = [](double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; };
  if (!finite_pos(handshake_timeout_s, 0.01, 3600)) return KeyError("handshake_timeout_s", "0.01..3600 seconds");
  if (!finite_pos(idle_timeout_s, 0.01, 86400)) return KeyError("idle_timeout_s", "0.01..86400 seconds");
  if (!(ping_interval_s == 0 || finite_pos(ping_interval_s, 0.01, 3600)))
    return KeyError("ping_interval_s", "0 (off) or 0.01..3600 seconds");
  if (queue_video_frames < 1 || queue_video_frames > 1000) return KeyError("queue_video_frames", "1..1000");
  if (queue_priority_messages < 16 || queue_priority_messages > 1000000)
    return KeyError("queue_priority_messages", "16..1000000");
  if (socket_send_buffer != 0 && (socket_send_buffer < 4096 || socket_send_buffer > (64 << 20)))
    return KeyError("socket_send_buffer", "0 (kernel default) or 4096..67108864 bytes");
  if (fragment_bytes < 1024 || fragment_bytes > (4u << 20)) return KeyError("fragment_bytes", "1024..4194304");
  if (threads < 1 || threads > 64) return KeyError("threads", "1..64");
  if (tls.enabled && (tls.cert_file.empty() || tls.key_file.empty()))
    return KeyError("tls", "enabled needs cert and key files");
  return layers.Check();
}

StatusOr<ServerConfig> ParseServerConfig(const std::string& yaml_text, const std::string& source) {
  HOLO_ASSIGN_OR_RETURN(YAML::Node root, LoadYaml(yaml_text, source));
  ServerConfig c;
  if (root.IsNull()) {
    Status s = c.Check();
    if (!s.ok()) return s.WithContext(source);
    return c;
  }
  if (!root.IsMap()) return InvalidArgument(source + ": expected a map of settings at the top level");
  auto parse = [&]() -> Status {
    HOLO_RETURN_IF_ERROR(CheckYamlKeys(root,
                                       {"name", "listen", "publisher_token", "viewer_token", "max_viewers",
                                        "max_publishers", "max_pending", "max_message_bytes", "handshake_timeout_s",
                                        "idle_timeout_s", "ping_interval_s", "queue_video_frames",
                                        "queue_priority_messages", "socket_send_buffer", "fragment_bytes", "threads",
                                        "tls", "layers"},
                                       ""));
    HOLO_RETURN_IF_ERROR(GetYamlString(root, "name", "", &c.name));
    std::string listen;
    HOLO_RETURN_IF_ERROR(GetYamlString(root, "listen", "", &listen));
    if (!listen.empty()) HOLO_RETURN_IF_ERROR(ParseHostPort(listen, &c.host, &c.port).WithContext("listen"));
    HOLO_RETURN_IF_ERROR(GetYamlString(root, "publisher_token", "", &c.publisher_token));
    HOLO_RETURN_IF_ERROR(GetYamlString(root, "viewer_token", "", &c.viewer_token));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "max_viewers", &c.max_viewers));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "max_publishers", &c.max_publishers));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "max_pending", &c.max_pending));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "max_message_bytes", &c.max_message_bytes));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "handshake_timeout_s", &c.handshake_timeout_s));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "idle_timeout_s", &c.idle_timeout_s));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "ping_interval_s", &c.ping_interval_s));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "queue_video_frames", &c.queue_video_frames));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "queue_priority_messages", &c.queue_priority_messages));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "socket_send_buffer", &c.socket_send_buffer));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "fragment_bytes", &c.fragment_bytes));
    HOLO_RETURN_IF_ERROR(GetNumber(root, "threads", &c.threads));
    const YAML::Node tls = root["tls"];
    if (tls.IsDefined()) {
      if (!tls.IsMap()) return KeyError("tls", "must be a map (enabled, cert, key)");
      HOLO_RETURN_IF_ERROR(CheckYamlKeys(tls, {"enabled", "cert", "key"}, "tls."));
      HOLO_RETURN_IF_ERROR(GetYamlBool(tls, "enabled", "", &c.tls.enabled).WithContext("tls"));
      HOLO_RETURN_IF_ERROR(GetYamlString(tls, "cert", "", &c.tls.cert_file).WithContext("tls"));
      HOLO_RETURN_IF_ERROR(GetYamlString(tls, "key", "", &c.tls.key_file).WithContext("tls"));
    }
    const YAML::Node layers = root["layers"];
    if (layers.IsDefined()) {
      if (!layers.IsMap()) return KeyError("layers", "must be a map (adaptive, up_hold_s, ...)");
      HOLO_RETURN_IF_ERROR(CheckYamlKeys(layers,
                                         {"adaptive", "down_queue_s", "kernel_backlog_s", "throughput_window_s", "busy_fraction",
                                          "down_throughput", "up_hold_s", "max_up_hold_s", "up_headroom", "stable_s",
                                          "probe_s"},
                                         "layers."));
      LayerPolicy& p = c.layers;
      HOLO_RETURN_IF_ERROR(GetYamlBool(layers, "adaptive", "", &p.adaptive).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "down_queue_s", &p.down_queue_s).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "kernel_backlog_s", &p.kernel_backlog_s).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "throughput_window_s", &p.throughput_window_s).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "busy_fraction", &p.busy_fraction).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "down_throughput", &p.down_throughput).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "up_hold_s", &p.up_hold_s).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "max_up_hold_s", &p.max_up_hold_s).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "up_headroom", &p.up_headroom).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "stable_s", &p.stable_s).WithContext("layers"));
      HOLO_RETURN_IF_ERROR(GetNumber(layers, "probe_s", &p.probe_s).WithContext("layers"));
    }
    return c.Check();
  };
  Status s = parse();
  if (!s.ok()) return s.WithContext(source);
  return c;
}

StatusOr<ServerConfig> LoadServerConfig(const std::string& path) {
  HOLO_ASSIGN_OR_RETURN(std::string text, ReadFileToString(path));
  HOLO_ASSIGN_OR_RETURN(ServerConfig c, ParseServerConfig(text, path));
  // Relative TLS paths are relative to the config file's folder.
  c.tls.cert_file = PathNextTo(path, c.tls.cert_file);
  c.tls.key_file = PathNextTo(path, c.tls.key_file);
  return c;
}

}  // namespace holo::net
