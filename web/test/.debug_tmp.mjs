import puppeteer from 'puppeteer-core';
import { spawn } from 'node:child_process';
const server = spawn(process.execPath, ['/work/wt-web/web/test/live_server.mjs', '/tmp/webfx/rec.hrec', '--page-dir', '/work/wt-web/web/dist'], { stdio: ['ignore', 'pipe', 'inherit'] });
const urls = await new Promise((res) => server.stdout.once('data', (d) => res(JSON.parse(String(d).split('\n')[0]))));
const browser = await puppeteer.launch({ executablePath: '/usr/bin/chromium', headless: true,
  args: ['--headless=new', '--no-sandbox', '--disable-gpu', '--use-gl=angle', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
  defaultViewport: { width: 640, height: 360, deviceScaleFactor: 1 } });
const page = await browser.newPage();
page.on('console', (m) => console.log('console:', m.type(), m.text().slice(0, 500)));
page.on('pageerror', (e) => console.log('pageerror', e.message));
await page.goto(`${urls.page}?src=${encodeURIComponent(urls.broadcast)}&${process.argv[2] || ''}`);
await new Promise((r) => setTimeout(r, 6000));
console.log(await page.evaluate(() => JSON.stringify({ ...window.holoport.state, geometryMs: undefined, colorMs: undefined, problems: window.holoport.state.problems.slice(0,3) })));
console.log(await page.evaluate(process.argv[3] || '1'));
await page.screenshot({ path: '/tmp/webfx/debug.png' });
await browser.close(); server.kill();
