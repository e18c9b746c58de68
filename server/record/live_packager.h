// The live packager (docs/broadcast.md): turns a live site stream into files
// an HTTP cache serves: segments (recording files, flag SEGMENT) that each
// start with the Rig in effect and a MeshFrame key frame, published also as
// parts of a few hundred ms (the segment's message records, byte for byte),
// and a live manifest `live.json` that advances after every part. Every file
// appears atomically (".name.tmp" then rename); old segments are pruned past
// a window; segment numbers continue across a site restart
// (Discontinuity()) and across a packager restart (Open() reads the
// directory's live.json and file names), so no name is reused.
//
//   auto p = *LivePackager::Open(options, now_unix_us);
//   for every whole message received:  p->AddMessage(frame, receive_unix_us);
//   every few ms:                      p->Tick(now_unix_us);
//   the site connection broke:         p->Discontinuity();
//   at the end:                        p->Finish(now_unix_us);
//
// Not thread-safe: one thread (or a mutex) drives it.
#pragma once

#include <cstdint>
#include <deque>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/status.h"
#include "server/record/recording_writer.h"

namespace holo::record {

struct LivePackagerOptions {
  // Directory the origin serves for this broadcast (created if missing).
  std::string dir;
  // Segment length aimed at, µs: a segment closes at the first MeshFrame key
  // frame at or after this much media. 2 s: a joining viewer waits ≤ 2 s for
  // a join point, and an edge makes ≤ 1 origin request per object.
  int64_t segment_us = 2000000;
  // Part length aimed at, µs: a part is published once this long has passed
  // since its first message. 250 ms ≈ 8 frames at 30 fps: latency grows by
  // about one part, requests per viewer by 4 per second.
  int64_t part_us = 250000;
  // Segments listed in live.json.
  int window_segments = 10;
  // Segments whose files stay on disk after leaving the list (players a little
  // behind still find them).
  int keep_extra_segments = 3;
  // Players key their live.json requests by time buckets of this length
  // (`?b=floor(unix_ms / cache_bucket_ms)`, docs/broadcast.md §4): the shipped
  // edges cache one copy per bucket, so the origin sees about one manifest
  // request per bucket per edge instead of one per viewer poll, and a copy is
  // never older than about a bucket (nginx itself caches in whole seconds,
  // longer than a part). 0: players send no bucket and every poll reaches the
  // origin. Written into live.json; below the part length.
  int cache_bucket_ms = 100;
  // How long an edge may serve a cached live.json, ms (written into it as
  // max(max_age_ms, cache_bucket_ms)).
  int max_age_ms = 0;
  // Stored in the segment files' header and live.json ("site:HOST:PORT").
  std::string source = "live";
  Status Check() const;
};

struct LivePartInfo {
  std::string name;
  int64_t start_us = 0;
  int64_t end_us = 0;
  uint64_t bytes = 0;
  uint64_t messages = 0;
  int64_t available_unix_us = 0;
};

struct LiveSegmentInfo {
  uint64_t number = 0;
  bool complete = false;
  bool discontinuity = false;
  int64_t start_us = 0;
  int64_t end_us = 0;
  uint64_t bytes = 0;
  std::vector<LivePartInfo> parts;
};

struct LivePackagerStats {
  uint64_t messages = 0;        // messages packaged
  uint64_t dropped_before_key = 0;  // content before the first key frame after a (re)start
  uint64_t rejected = 0;        // invalid messages (not packaged; the broadcast goes on)
  uint64_t ignored_types = 0;   // valid messages of types a broadcast does not carry (Ping, Pong, ...)
  uint64_t parts = 0;
  uint64_t segments = 0;        // segments closed
  uint64_t pruned_segments = 0; // segments whose files were deleted
  uint64_t keyframe_requests = 0;   // times WantsKeyFrame said yes
};

// Segment and part names: seg_00042.hrec, seg_00042.p3.
std::string LiveSegmentFileName(uint64_t number);
std::string LivePartName(uint64_t number, uint64_t part);

class LivePackager {
 public:
  // Opens (or continues) the broadcast in `options.dir`. A live.json there
  // (from an earlier run) keeps its availability start and listed complete
  // segments; numbering continues after the largest segment number found in
  // live.json or in file names, and the first new segment is a
  // discontinuity. Errors: InvalidArgument (options), DataLoss (a live.json
  // that does not parse or a different format), Unavailable (I/O).
  static StatusOr<std::unique_ptr<LivePackager>> Open(LivePackagerOptions options, int64_t now_unix_us);
  ~LivePackager();
  LivePackager(const LivePackager&) = delete;
  LivePackager& operator=(const LivePackager&) = delete;

  // One whole protocol message (32-byte header + payload, not a fragment) as
  // received at `receive_unix_us`. Rig messages are remembered (each segment
  // starts with the one in effect); content before the first key frame after
  // a (re)start is dropped. Types a broadcast does not carry (session
  // messages such as Pong) are ignored and counted. An invalid message
  // returns InvalidArgument and is not packaged (the broadcast goes on);
  // Unavailable: writing failed.
  Status AddMessage(std::span<const uint8_t> frame, int64_t receive_unix_us);
  // Publishes the open part if it is due at `now_unix_us`.
  Status Tick(int64_t now_unix_us);
  // The site stream broke (disconnect, site restart): closes the open segment;
  // the next one is marked discontinuity and waits for a new Rig and key frame.
  Status Discontinuity(int64_t now_unix_us);
  // Closes the open segment and writes live.json with ended = true.
  Status Finish(int64_t now_unix_us);
  // True when the site should be asked for a key frame now (Control
  // kRequestKeyFrame): the open segment has reached its target length, or
  // no segment is open (a join or a restart waits for one). With
  // inter-frame colour (V1) a site sends a whole-frame key frame only every
  // keyframe interval unless asked, so a packager that does not ask gets
  // segments of up to segment + interval. At most once per part length;
  // counted in stats().keyframe_requests.
  bool WantsKeyFrame(int64_t now_unix_us);

  int64_t availability_start_unix_us() const { return availability_start_; }
  const std::deque<LiveSegmentInfo>& window() const { return window_; }
  const LivePackagerStats& stats() const { return stats_; }
  uint64_t next_segment() const { return next_segment_; }

 private:
  explicit LivePackager(LivePackagerOptions options);
  Status Load(int64_t now_unix_us);
  Status StartSegment(int64_t t);
  Status PublishPart(int64_t now_unix_us);
  Status CloseSegment(int64_t now_unix_us);
  Status WriteManifest(int64_t now_unix_us, bool ended);
  Status Prune();
  int64_t MediaTime(int64_t unix_us);

  LivePackagerOptions options_;
  int64_t availability_start_ = 0;
  int64_t last_time_ = 0;
  uint64_t next_segment_ = 0;
  bool next_discontinuity_ = false;
  std::deque<LiveSegmentInfo> window_;    // listed segments; the back one may be open
  std::deque<uint64_t> pruned_pending_;   // left the list, files still on disk
  std::unique_ptr<RecordingWriter> writer_;  // the open segment's file (temporary name)
  bool open_ = false;                      // a segment is open (window_.back())
  std::vector<uint8_t> part_;              // records of the open part
  uint64_t part_messages_ = 0;
  int64_t part_start_ = 0, part_end_ = 0;
  std::vector<uint8_t> rig_;               // the Rig in effect (whole frame)
  int64_t last_keyframe_request_ = INT64_MIN;
  LivePackagerStats stats_;
};

}  // namespace holo::record
