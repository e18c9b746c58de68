// A live broadcast over HTTP (docs/broadcast.md): polls live.json, joins at
// the live edge (a segment's part 0: Rig + key frame), fetches parts in
// order, splits them into messages, and reports trouble (a damaged or missing
// part, a stalled edge) through `onStatus` without ever stopping: it keeps
// polling and recovers when data returns.

import { parseRecords } from './protocol.js';

export function partName(segment, part) {
  return `seg_${String(segment).padStart(5, '0')}.p${part}`;
}

export class LiveSource {
  // url: the manifest URL (…/live.json, query string kept for signed URLs).
  // onMessages(messages, info): a part's messages, in order; info = {segment,
  //   part, bytes, discontinuity, availabilityStartUs}.
  // onStatus({level: 'ok'|'warn'|'error', text}).
  constructor(url, { onMessages, onStatus, stallMs = 3000, fetchImpl = fetch.bind(globalThis) }) {
    this.url = new URL(url, globalThis.location ? globalThis.location.href : undefined);
    this.query = this.url.search;
    this.base = new URL('.', this.url);
    this.onMessages = onMessages;
    this.onStatus = onStatus;
    this.stallMs = stallMs;
    this.fetch = fetchImpl;
    this.manifest = null;
    this.next = null;          // {segment, part} to fetch next
    this.lastDataMs = 0;       // performance.now() of the last part received
    this.stopped = false;
    this.problem = null;       // the current trouble's text, null when healthy
    this.bytes = 0;
    this.parts = 0;
    this.errors = 0;
    this.prefetch = null;      // {url, promise} of the part fetched ahead
  }

  objectUrl(name) {
    return new URL(name + this.query, this.base).href;
  }

  setProblem(text, level = 'warn') {
    if (text === this.problem) return;
    this.problem = text;
    this.onStatus(text ? { level, text } : { level: 'ok', text: '' });
  }

  // The manifest's URL: once a manifest names its cache bucket, polls carry
  // b = floor(Unix ms / cache_bucket_ms), so an edge keeps one copy per
  // bucket for all its viewers (docs/broadcast.md §4).
  manifestUrl(nowMs = Date.now()) {
    const bucket = this.manifest && this.manifest.cache_bucket_ms;
    if (!Number.isInteger(bucket) || bucket <= 0 || bucket > 60000) return this.url.href;
    const u = new URL(this.url.href);
    u.searchParams.set('b', String(Math.floor(nowMs / bucket)));
    return u.href;
  }

  async fetchManifest() {
    const res = await this.fetchWithTimeout(this.manifestUrl(), 4000, { cache: 'no-store' });
    if (!res.ok) throw new Error(`live.json: HTTP ${res.status}`);
    const m = JSON.parse(new TextDecoder().decode(res.body));
    if (m.format !== 'holoport-live') throw new Error('live.json: not a holoport-live manifest');
    if (m.version !== 1) throw new Error(`live.json: version ${m.version} is not supported`);
    if (!Array.isArray(m.segments)) throw new Error('live.json: no segments');
    this.manifest = m;
    return m;
  }

  // The newest segment whose part 0 is listed (the live edge's join point).
  joinPoint(m) {
    for (let i = m.segments.length - 1; i >= 0; --i) {
      const s = m.segments[i];
      if (s.parts && s.parts.length > 0) return { segment: s.number, part: 0 };
    }
    return null;
  }

  segmentOf(m, n) {
    return m.segments.find((s) => s.number === n) || null;
  }

  // What follows {segment, part} by the manifest (docs/broadcast.md §4.3):
  // the next part of an open segment (or one it lists), else the first part
  // of the next listed segment; null when that is not listed yet.
  following(m, pos) {
    const seg = this.segmentOf(m, pos.segment);
    if (seg && (pos.part + 1 < seg.parts.length || !seg.complete)) return { segment: pos.segment, part: pos.part + 1 };
    const later = m.segments.find((s) => s.number > pos.segment && s.parts.length > 0);
    return later ? { segment: later.number, part: 0 } : null;
  }

  // Broadcast time of the newest listed message (the end of the newest part).
  liveEdgeUs(m) {
    let edge = 0;
    for (const seg of m.segments) for (const p of seg.parts) if (Number.isFinite(p.end_us)) edge = Math.max(edge, p.end_us);
    return edge;
  }

  listed(m, pos) {
    const seg = this.segmentOf(m, pos.segment);
    return !!(seg && pos.part < seg.parts.length);
  }

  // Skip to the part 0 of the next segment after `segment` that the manifest
  // lists (or the live edge).
  skipSegment(m, segment) {
    const later = m.segments.filter((s) => s.number > segment && s.parts.length > 0);
    return later.length ? { segment: later[0].number, part: 0 } : null;
  }

  // fetch with a deadline: a stalled edge must not hang the player.
  async fetchWithTimeout(url, ms, init = {}) {
    const ctrl = new AbortController();
    const timer = setTimeout(() => ctrl.abort(), ms);
    try {
      const res = await this.fetch(url, { ...init, signal: ctrl.signal });
      const body = new Uint8Array(await res.arrayBuffer());
      return { ok: res.ok, status: res.status, body };
    } catch (e) {
      throw new Error(ctrl.signal.aborted ? `no answer within ${ms / 1000} s` : e.message);
    } finally {
      clearTimeout(timer);
    }
  }

  // Watchdog: nothing new for stallMs → tell the viewer (the fetch loop may
  // be waiting on a request that does not answer).
  watchStall() {
    this.watchdog = setInterval(() => {
      const idle = performance.now() - this.lastDataMs;
      const ended = this.manifest && this.manifest.ended;
      if (!ended && idle > this.stallMs) {
        this.setProblem(`No new data from the edge for ${Math.floor(idle / 1000)} s — waiting for the broadcast to resume…`, 'error');
      }
    }, 500);
  }

  async run() {
    this.watchStall();
    const poll = () => Math.max(100, (this.manifest && this.manifest.update_interval_ms) || 250);
    let lastManifestMs = 0;
    this.lastDataMs = performance.now();
    let skipAfter = -1;  // a damaged/missing part in this segment: resume at the next one
    while (!this.stopped) {
      const now = performance.now();
      // The manifest is refreshed when the next part is not listed yet (every
      // update interval), and at least every 2 s; parts already listed are
      // fetched back to back, so a player that is behind catches up.
      const waiting = !this.manifest || !this.next || skipAfter >= 0 || !this.listed(this.manifest, this.next);
      if (!this.manifest || (waiting && now - lastManifestMs >= poll()) || now - lastManifestMs >= 2000) {
        try {
          await this.fetchManifest();
          lastManifestMs = performance.now();
        } catch (e) {
          lastManifestMs = performance.now();
          this.errors++;
          this.setProblem(`Cannot load the broadcast manifest (${e.message}); retrying…`, 'error');
          await sleep(Math.min(1000, poll() * 2));
          continue;
        }
      }
      const m = this.manifest;
      if (!this.next) {
        this.next = this.joinPoint(m);
        if (!this.next) {
          this.setProblem(m.ended ? 'The broadcast has ended.' : 'Waiting for the broadcast to start…');
          await sleep(poll());
          continue;
        }
      }
      if (skipAfter >= 0) {
        const n = this.skipSegment(m, skipAfter);
        if (!n) {
          await sleep(poll());
          continue;
        }
        this.next = n;
        skipAfter = -1;
      }
      // Catch up when far behind (more than ~2 segments).
      const edge = this.joinPoint(m);
      if (edge && edge.segment - this.next.segment > 2) this.next = edge;
      // A segment that fell out of the window: go to the oldest listed one.
      if (m.segments.length && this.next.segment < m.segments[0].number) this.next = this.joinPoint(m);
      if (!this.listed(m, this.next) && this.next.part === 0) {
        // The segment we wait for is absent but a later one is listed: go there.
        const after = this.next.segment;
        const later = m.segments.find((s) => s.number > after && s.parts.length > 0);
        if (later) this.next = { segment: later.number, part: 0 };
      }
      const pos = this.next;
      if (!this.listed(m, pos)) {
        if (m.ended && !this.following(m, pos)) this.setProblem('The broadcast has ended.');
        // Not listed yet: the edge may be stalled if nothing came for a while.
        await sleep(poll());
        continue;
      }
      const seg = this.segmentOf(m, pos.segment);
      let res;
      try {
        const url = this.objectUrl(partName(pos.segment, pos.part));
        const pre = this.prefetch && this.prefetch.url === url ? this.prefetch.promise : null;
        this.prefetch = null;
        res = await (pre || this.fetchWithTimeout(url, 10000));
        // The part after it, if listed, is fetched while this one is checked and decoded.
        const after = this.following(m, pos);
        if (after && this.listed(m, after)) {
          const u = this.objectUrl(partName(after.segment, after.part));
          const promise = this.fetchWithTimeout(u, 10000);
          promise.catch(() => {});  // its error is handled when it is awaited
          this.prefetch = { url: u, promise };
        }
      } catch (e) {
        this.errors++;
        this.setProblem(`Network error fetching ${partName(pos.segment, pos.part)} (${e.message}); retrying…`, 'error');
        await sleep(poll());
        continue;
      }
      if (!res.ok) {
        this.errors++;
        this.setProblem(`Part ${partName(pos.segment, pos.part)} is unavailable (HTTP ${res.status}); skipping to the next segment…`);
        skipAfter = pos.segment;
        continue;
      }
      const bytes = res.body;
      let messages;
      try {
        messages = parseRecords(bytes);
        if (pos.part === 0 && (!messages.length || messages[0].header.type !== 4)) {
          throw new Error('part 0 does not start with the Rig');
        }
      } catch (e) {
        this.errors++;
        this.setProblem(`Part ${partName(pos.segment, pos.part)} is damaged (${e.message}); skipping to the next segment…`);
        skipAfter = pos.segment;
        continue;
      }
      this.bytes += bytes.length;
      this.parts++;
      this.lastDataMs = performance.now();
      this.setProblem(null);
      this.onMessages(messages, {
        segment: pos.segment, part: pos.part, bytes: bytes.length,
        discontinuity: pos.part === 0 && !!(seg && seg.discontinuity),
        availabilityStartUs: m.availability_start_unix_us,
        liveEdgeUs: this.liveEdgeUs(m), targetPartUs: m.target_part_us || 250000,
      });
      this.next = this.following(m, pos) || { segment: pos.segment + 1, part: 0 };
    }
  }

  stop() {
    this.stopped = true;
    clearInterval(this.watchdog);
  }
}

function sleep(ms) {
  return new Promise((r) => setTimeout(r, ms));
}
