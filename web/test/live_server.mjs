// A live broadcast for tests, in the format of docs/broadcast.md, served
// from a recording as if it were being captured now: the recording is cut
// into segments (each starting with the Rig in effect and a MeshFrame key
// frame, at the first key frame at or after every 2 s) and parts (~250 ms),
// and a part becomes available (listed in live.json and fetchable) when its
// last message's broadcast time has passed. At its end the recording starts
// again (a `discontinuity` segment), so the broadcast never ends.
//
// Faults for tests (POST or GET):
//   /control/corrupt   the next part requested is served damaged (one byte
//                      of a record body flipped: CRC mismatch), and so is
//                      every later request for that part
//   /control/stall?ms=N    for N ms the manifest stops advancing and every
//                      request waits until the stall is over
//
// Serves the broadcast at http://127.0.0.1:PORT/live/ with the edges' CORS
// and cache headers, and (optionally) a static directory (the built page)
// on a second port, so the page and the broadcast have different origins as
// with a real edge.
//
// Usage: node live_server.mjs RECORDING [--port P] [--page-dir DIR --page-port Q] [--preroll-ms MS]
// Prints one JSON line {"broadcast": URL, "page": URL} when ready.

import { createServer } from 'node:http';
import { readFileSync, existsSync, statSync } from 'node:fs';
import { join, extname, normalize } from 'node:path';
import { parseRecording, MSG } from '../src/protocol.js';
import { crc32c } from '../src/bytes.js';

const args = process.argv.slice(2);
function opt(name, def) {
  const i = args.indexOf(name);
  return i >= 0 ? args[i + 1] : def;
}
const recordingPath = args[0];
if (!recordingPath || recordingPath.startsWith('--')) {
  console.error('usage: node live_server.mjs RECORDING [--port P] [--page-dir DIR --page-port Q] [--preroll-ms MS]');
  process.exit(2);
}
const known = new Set(['--port', '--page-dir', '--page-port', '--preroll-ms', '--segment-ms', '--part-ms']);
for (let i = 1; i < args.length; i += 2) {
  if (!known.has(args[i])) {
    console.error(`live_server: unknown option ${args[i]}`);
    process.exit(2);
  }
}
const port = Number(opt('--port', 0));
const pageDir = opt('--page-dir', null);
const pagePort = Number(opt('--page-port', 0));
const prerollUs = Number(opt('--preroll-ms', 2500)) * 1000;
const segmentUs = Number(opt('--segment-ms', 2000)) * 1000;
const partUs = Number(opt('--part-ms', 250)) * 1000;

// ---------------------------------------------------------------- cutting

function encodeRecord(timeUs, body) {
  const rec = new Uint8Array(24 + body.length);
  const dv = new DataView(rec.buffer);
  dv.setUint32(0, 0x4d524c48, true);
  rec[4] = 1;
  dv.setUint32(8, body.length, true);
  dv.setBigInt64(16, BigInt(timeUs), true);
  rec.set(body, 24);
  let c = crc32c(rec.subarray(0, 12));
  c = crc32c(rec.subarray(16, 24), c);
  c = crc32c(body, c);
  dv.setUint32(12, c, true);
  return rec;
}

const file = new Uint8Array(readFileSync(recordingPath));
const messages = parseRecording(file);
const duration = messages[messages.length - 1].timeUs;
const loopUs = duration + 33333;
// One pass of the recording as segments of parts: [{start, parts: [{start, end, records: [Uint8Array]}]}],
// times relative to the pass.
function cutPass() {
  const segs = [];
  let rig = null, seg = null, part = null;
  for (const m of messages) {
    const whole = new Uint8Array(m.payload.buffer, m.payload.byteOffset - 32, m.payload.length + 32);
    if (m.header.type === MSG.RIG) {
      rig = whole;
      continue;
    }
    const key = m.header.type === MSG.MESH && m.header.keyFrame;
    if (key && rig && (!seg || m.timeUs >= seg.start + segmentUs)) {
      seg = { start: m.timeUs, parts: [] };
      segs.push(seg);
      part = { start: m.timeUs, end: m.timeUs, records: [{ t: m.timeUs, body: rig }] };
      seg.parts.push(part);
    }
    if (!seg) continue;  // before the first key frame
    if (m.timeUs >= part.start + partUs) {
      part = { start: m.timeUs, end: m.timeUs, records: [] };
      seg.parts.push(part);
    }
    part.records.push({ t: m.timeUs, body: whole });
    part.end = m.timeUs;
  }
  return segs;
}
const pass = cutPass();

const availabilityStartUs = Date.now() * 1000 - prerollUs;
let stallUntilMs = 0;
let frozenNowUs = null;  // broadcast time frozen during a stall
let corruptNext = false;
const corrupted = new Set();

function broadcastNowUs() {
  const real = Date.now() * 1000 - availabilityStartUs;
  if (Date.now() < stallUntilMs) {
    if (frozenNowUs === null) frozenNowUs = real;
    return frozenNowUs;
  }
  frozenNowUs = null;
  return real;
}

// Segment number n: pass floor(n / pass.length), index n % pass.length.
function segmentInfo(n) {
  const k = Math.floor(n / pass.length), s = pass[n % pass.length];
  const off = k * loopUs;
  return { n, off, s, discontinuity: k > 0 && n % pass.length === 0 };
}
function partBytes(n, p) {
  const { off, s } = segmentInfo(n);
  const recs = s.parts[p].records.map((r) => encodeRecord(r.t + off, r.body));
  const out = new Uint8Array(recs.reduce((a, r) => a + r.length, 0));
  let o = 0;
  for (const r of recs) {
    out.set(r, o);
    o += r.length;
  }
  return out;
}
const name = (n, p) => `seg_${String(n).padStart(5, '0')}.p${p}`;

// The parts available now: [{n, p}] in order (every part whose end has passed).
function available(nowUs) {
  const out = [];
  for (let n = 0; ; ++n) {
    const { off, s } = segmentInfo(n);
    if (off + s.start > nowUs) break;
    for (let p = 0; p < s.parts.length; ++p) {
      if (off + s.parts[p].end <= nowUs) out.push({ n, p });
    }
  }
  return out;
}

function manifest() {
  const now = broadcastNowUs();
  const av = available(now);
  const bySeg = new Map();
  for (const { n, p } of av) {
    if (!bySeg.has(n)) bySeg.set(n, []);
    bySeg.get(n).push(p);
  }
  const numbers = [...bySeg.keys()].slice(-10);
  const segments = numbers.map((n) => {
    const { off, s, discontinuity } = segmentInfo(n);
    const ps = bySeg.get(n);
    const complete = ps.length === s.parts.length;
    const parts = ps.map((p) => ({
      name: name(n, p), start_us: off + s.parts[p].start, end_us: off + s.parts[p].end,
      bytes: partBytes(n, p).length, messages: s.parts[p].records.length,
      available_unix_us: availabilityStartUs + off + s.parts[p].end,
    }));
    return {
      number: n, file: null, complete, discontinuity,
      start_us: off + s.start, end_us: parts[parts.length - 1].end_us,
      bytes: parts.reduce((a, p) => a + p.bytes, 0), parts,
    };
  });
  return {
    format: 'holoport-live', version: 1, source: `recording:${recordingPath}`,
    availability_start_unix_us: availabilityStartUs, published_unix_us: Date.now() * 1000,
    target_segment_us: segmentUs, target_part_us: partUs, update_interval_ms: partUs / 1000, max_age_ms: 100,
    cache_bucket_ms: 100,
    window_segments: 10, keep_extra_segments: 3, ended: false,
    next_segment: numbers.length ? numbers[numbers.length - 1] + 1 : 0, segments,
  };
}

// ---------------------------------------------------------------- HTTP

const cors = {
  'Access-Control-Allow-Origin': '*',
  'Access-Control-Allow-Methods': 'GET, HEAD, OPTIONS',
  'Access-Control-Allow-Headers': '*',
};

async function waitStall() {
  while (Date.now() < stallUntilMs) await new Promise((r) => setTimeout(r, 50));
}

const server = createServer(async (req, res) => {
  const url = new URL(req.url, 'http://x');
  if (req.method === 'OPTIONS') {
    res.writeHead(204, cors);
    return res.end();
  }
  if (url.pathname === '/control/corrupt') {
    corruptNext = true;
    res.writeHead(200, cors);
    return res.end('ok');
  }
  if (url.pathname === '/control/stall') {
    stallUntilMs = Date.now() + Number(url.searchParams.get('ms') || 5000);
    res.writeHead(200, cors);
    return res.end('ok');
  }
  await waitStall();
  if (url.pathname === '/live/live.json') {
    const body = JSON.stringify(manifest());
    res.writeHead(200, { ...cors, 'Content-Type': 'application/json', 'Cache-Control': 'public, max-age=1' });
    return res.end(body);
  }
  const m = /^\/live\/seg_(\d{5,})\.p(\d+)$/.exec(url.pathname);
  if (m) {
    const n = Number(m[1]), p = Number(m[2]);
    const ok = available(broadcastNowUs()).some((a) => a.n === n && a.p === p);
    if (!ok) {
      res.writeHead(404, { ...cors, 'Cache-Control': 'max-age=1' });
      return res.end();
    }
    let bytes = partBytes(n, p);
    if (corruptNext) {
      corrupted.add(name(n, p));
      corruptNext = false;
    }
    if (corrupted.has(name(n, p))) {
      bytes = bytes.slice();
      bytes[Math.min(bytes.length - 1, 24 + 40)] ^= 0x5a;
    }
    res.writeHead(200, {
      ...cors, 'Content-Type': 'application/octet-stream', 'Content-Length': bytes.length,
      'Cache-Control': 'public, max-age=31536000, immutable',
    });
    return res.end(bytes);
  }
  res.writeHead(404, cors);
  res.end();
});

const types = { '.html': 'text/html; charset=utf-8', '.js': 'text/javascript', '.css': 'text/css' };
const pageServer = pageDir && createServer((req, res) => {
  const path = new URL(req.url, 'http://x').pathname;
  const rel = normalize(path === '/' ? '/index.html' : path).replace(/^(\.\.[/\\])+/, '');
  const full = join(pageDir, rel);
  if (!full.startsWith(pageDir) || !existsSync(full) || !statSync(full).isFile()) {
    res.writeHead(404);
    return res.end();
  }
  res.writeHead(200, { 'Content-Type': types[extname(full)] || 'application/octet-stream' });
  res.end(readFileSync(full));
});

server.listen(port, '127.0.0.1', () => {
  const bport = server.address().port;
  const done = (pport) => console.log(JSON.stringify({
    broadcast: `http://127.0.0.1:${bport}/live/live.json`,
    page: pport ? `http://127.0.0.1:${pport}/` : null,
    control: `http://127.0.0.1:${bport}/control/`,
    segments_per_pass: pass.length, pass_seconds: loopUs / 1e6,
  }));
  if (pageServer) pageServer.listen(pagePort, '127.0.0.1', () => done(pageServer.address().port));
  else done(0);
});
