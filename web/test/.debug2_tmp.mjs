import puppeteer from 'puppeteer-core';
import { spawn } from 'node:child_process';
const server = spawn(process.execPath, ['/work/wt-web/web/test/live_server.mjs', '/work/wt-web/build/web-fixture/rec.hrec', '--page-dir', '/work/wt-web/web/dist'], { stdio: ['ignore', 'pipe', 'inherit'] });
const urls = await new Promise((res) => server.stdout.once('data', (d) => res(JSON.parse(String(d).split('\n')[0]))));
const browser = await puppeteer.launch({ executablePath: '/usr/bin/chromium', headless: true,
  args: ['--headless=new', '--no-sandbox', '--disable-gpu', '--use-gl=angle', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--autoplay-policy=no-user-gesture-required'],
  defaultViewport: { width: 640, height: 360, deviceScaleFactor: 1 } });
const page = await browser.newPage();
page.on('pageerror', (e) => console.log('pageerror', e.message));
await page.goto(`${urls.page}?src=${encodeURIComponent(urls.broadcast)}&voice=1&overlay=0`);
for (let i = 0; i < 10; ++i) {
  await new Promise((r) => setTimeout(r, 1000));
  console.log(await page.evaluate(() => { const s = window.holoport.state; return JSON.stringify({ f: s.framesShown, a: s.audioChunks, parts: s.parts, media: s.mediaUs, lat: s.latencyMs, buf: s.bufferMs, p: s.problems.length }); }));
}
await browser.close(); server.kill();
