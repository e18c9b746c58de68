// LiveSource (web/src/live.js) against a scripted edge (no browser, no
// network): which parts it fetches in which order, and what it tells the
// viewer, when it joins, follows a growing manifest, meets a 404, a damaged
// part, a gap in the segment numbers, and a manifest that stops advancing.
//
// Usage: node live_test.mjs

import { LiveSource } from '../src/live.js';
import { crc32c } from '../src/bytes.js';
import { colourAction } from '../src/person.js';

let failures = 0;
function check(cond, what) {
  console.log(`${cond ? 'ok' : 'FAIL'}: ${what}`);
  if (!cond) failures++;
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// One message record holding a protocol frame of `type` (payload empty).
function record(type, timeUs) {
  const body = new Uint8Array(32);
  const h = new DataView(body.buffer);
  h.setUint32(0, 0x54504c48, true);
  h.setUint16(4, 1, true);
  h.setUint16(6, type, true);
  const rec = new Uint8Array(24 + 32);
  const dv = new DataView(rec.buffer);
  dv.setUint32(0, 0x4d524c48, true);
  rec[4] = 1;
  dv.setUint32(8, 32, true);
  dv.setBigInt64(16, BigInt(timeUs), true);
  rec.set(body, 24);
  let c = crc32c(rec.subarray(0, 12));
  c = crc32c(rec.subarray(16, 24), c);
  c = crc32c(body, c);
  dv.setUint32(12, c, true);
  return rec;
}

// The scripted edge: segments {number, parts: count, complete}; parts named
// in `missing` answer 404, in `damaged` a corrupt record.
const edge = { segments: [], missing: new Set(), damaged: new Set(), requests: [], urls: [], frozen: false, bucketMs: undefined };
const name = (n, p) => `seg_${String(n).padStart(5, '0')}.p${p}`;
function manifest() {
  return {
    format: 'holoport-live', version: 1, availability_start_unix_us: 0, update_interval_ms: 100, ended: false,
    cache_bucket_ms: edge.bucketMs,
    segments: edge.segments.map((s) => ({
      number: s.number, complete: s.complete, discontinuity: false,
      parts: Array.from({ length: s.parts }, (_, p) => ({ name: name(s.number, p) })),
    })),
  };
}
async function fakeFetch(url) {
  const path = new URL(url).pathname.split('/').pop();
  edge.requests.push(path);
  edge.urls.push(url);
  const reply = (status, bytes) => ({ ok: status === 200, status, arrayBuffer: async () => bytes.buffer });
  if (path === 'live.json') return reply(200, new TextEncoder().encode(JSON.stringify(manifest())));
  const m = /^seg_(\d+)\.p(\d+)$/.exec(path);
  if (!m || edge.missing.has(path)) return reply(404, new Uint8Array(0));
  const n = Number(m[1]), p = Number(m[2]);
  const rec = record(p === 0 ? 4 : 7, n * 1000000 + p * 250000);
  if (edge.damaged.has(path)) rec[30] ^= 1;
  return reply(200, rec);
}

const got = [], statuses = [];
const live = new LiveSource('http://edge.test/b/live.json', {
  fetchImpl: fakeFetch, stallMs: 800,
  onMessages: (msgs, info) => got.push(name(info.segment, info.part)),
  onStatus: (s) => statuses.push(s.text),
});
edge.segments = [{ number: 3, parts: 4, complete: true }, { number: 4, parts: 2, complete: false }];
live.run();
await sleep(400);
check(got[0] === 'seg_00004.p0', `joins at the newest segment's part 0 (${got[0]})`);
check(got.join() === 'seg_00004.p0,seg_00004.p1', `follows its parts (${got.join()})`);
edge.segments[1] = { number: 4, parts: 4, complete: true };
edge.segments.push({ number: 5, parts: 3, complete: false });
edge.missing.add('seg_00005.p1');
await sleep(500);
check(got.includes('seg_00004.p3') && got.includes('seg_00005.p0'), 'continues into the next segment');
check(!got.includes('seg_00005.p1') && !got.includes('seg_00005.p2'), 'a 404 skips the rest of its segment');
check(statuses.some((t) => /seg_00005\.p1 is unavailable \(HTTP 404\)/.test(t)), 'the 404 is reported by name');
// A gap: segment 6 never appears; 7 does, with a damaged part 1.
edge.segments = [{ number: 5, parts: 3, complete: true }, { number: 7, parts: 3, complete: false }];
edge.damaged.add('seg_00007.p1');
await sleep(500);
check(got.includes('seg_00007.p0'), 'jumps over a missing segment number');
check(!got.includes('seg_00007.p1') && statuses.some((t) => /seg_00007\.p1 is damaged/.test(t)), 'a damaged part is reported and skipped');
edge.segments.push({ number: 8, parts: 1, complete: false });
await sleep(500);
check(got[got.length - 1] === 'seg_00008.p0', `resumes at the next segment (${got[got.length - 1]})`);
check(statuses[statuses.length - 1] === '', 'the message clears when data flows again');
// The manifest stops advancing: a stall message, then recovery.
await sleep(1200);
check(/No new data from the edge/.test(statuses[statuses.length - 1]), 'a stalled edge is reported');
edge.segments[edge.segments.length - 1].parts = 2;
await sleep(400);
check(got[got.length - 1] === 'seg_00008.p1' && statuses[statuses.length - 1] === '', 'recovers when parts come again');
const order = got.map((g) => g.slice(4)).join(' ');
console.log(`fetched in order: ${order}`);
live.stop();

// The manifest's cache bucket: the first poll carries none (the manifest names
// it), later polls b = floor(now / bucket), the signature kept; a bucket out of
// range is ignored.
edge.bucketMs = 100;
edge.urls.length = 0;
const signed = new LiveSource('http://edge.test/b/live.json?md5=aB-_9&expires=17', {
  fetchImpl: fakeFetch, onMessages: () => {}, onStatus: () => {},
});
await signed.fetchManifest();
const before = Date.now();
await signed.fetchManifest();
const after = Date.now();
const first = new URL(edge.urls[0]), second = new URL(edge.urls[1]);
check(!first.searchParams.has('b') && first.searchParams.get('md5') === 'aB-_9', `first poll without a bucket (${edge.urls[0]})`);
const b = Number(second.searchParams.get('b'));
check(b >= Math.floor(before / 100) && b <= Math.floor(after / 100), `later polls carry the bucket (${edge.urls[1]})`);
check(second.searchParams.get('md5') === 'aB-_9' && second.searchParams.get('expires') === '17', 'the signature is kept');
check(second.pathname === '/b/live.json', 'same manifest path');
signed.manifest.cache_bucket_ms = 0;
check(!new URL(signed.manifestUrl()).searchParams.has('b'), 'no bucket when the manifest names none');
signed.manifest.cache_bucket_ms = 1e9;
check(!new URL(signed.manifestUrl()).searchParams.has('b'), 'a bucket out of range is ignored');

// Colour paired with meshes (person.js): exact frames are applied, colour
// ahead of its mesh is held, colour of a replaced mesh is applied when newer
// than what is shown — a live V1 stream decodes colour a few frames behind
// its geometry, and the person must not stay uncoloured (it did: a G3 + V1
// broadcast showed a grey person in Chromium).
check(colourAction(10, 10, -1) === 'apply' && colourAction(10, 10, 9) === 'apply', 'exact frame applied');
check(colourAction(10, 12, 9) === 'hold', 'colour ahead of its mesh is held');
check(colourAction(13, 10, -1) === 'apply', 'lagging colour applied when nothing is shown');
check(colourAction(13, 11, 10) === 'apply', 'lagging colour applied when newer than the shown');
check(colourAction(13, 9, 10) === 'drop', 'colour older than the shown is dropped');
let shown = -1, applied = 0;
for (let mesh = 0; mesh < 30; ++mesh) {  // colour 3 frames behind the geometry
  const img = mesh - 3;
  if (img >= 0 && colourAction(mesh, img, shown) === 'apply') { shown = img; applied++; }
}
check(applied === 27 && shown === 26, `a person whose colour lags 3 frames is coloured every frame (${applied} of 27)`);
if (failures) {
  console.log(`${failures} failure(s)`);
  process.exit(1);
}
console.log('live: all checks passed');
