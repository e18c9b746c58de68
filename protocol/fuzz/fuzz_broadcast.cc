// libFuzzer target: the broadcast player's parsers of network input
// (client/net/broadcast_player.h): the HTTP response head (fed whole and in
// two pieces) and the live manifest.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "client/net/broadcast_player.h"
#include "common/status.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::span<const uint8_t> bytes(data, size);
  bool complete = false;
  auto head = holo::net::ParseHttpResponseHead(bytes, &complete);
  if (head.ok() && complete) {
    HOLO_CHECK(head->head_bytes <= size);
    HOLO_CHECK(head->status >= 100 && head->status <= 999);
  }
  auto m = holo::net::ParseLiveManifest(std::string_view(reinterpret_cast<const char*>(data), size));
  if (m.ok()) {
    for (size_t i = 1; i < m->segments.size(); ++i) HOLO_CHECK(m->segments[i].number > m->segments[i - 1].number);
    HOLO_CHECK(m->cache_bucket_ms >= 0 && m->cache_bucket_ms <= 60000);
    const std::string target = holo::net::ManifestTarget(holo::net::BroadcastUrl{"e", 80, "/s/", ""}, m->cache_bucket_ms,
                                                         1700000000000);
    HOLO_CHECK(target.rfind("/s/live.json", 0) == 0);
    holo::net::LiveFollower f;
    f.OnManifest(*m);
    for (int i = 0; i < 64; ++i) {
      auto p = f.Next();
      if (!p) break;
      if (i % 3 == 2) f.Skip(*p); else f.Done(*p);
    }
  }
  return 0;
}
