// The browser view's figures (docs/benchmarks.md, "Browser view"): how long a mesh takes from
// being published to being drawn by the page (loopback), and the page's frame rate with three
// labels of about 200k triangles each, in Debian's chromium headless (software WebGL).
//
// node bench/viewer_bench.mjs SONOSHAPE SONOSHAPE_VIEWER_PUBLISHER WORK_DIR [--sizes 20000,200000]
//     [--updates 10] [--interval-ms 1000,4000] [--fps-seconds 5]
// (--interval-ms per size: long enough for the page to draw every update, so that the latency
// is the page's own and not a queue's.)
// e.g. node bench/viewer_bench.mjs build/apps/sonoshape build/bench/sonoshape_viewer_publisher /tmp/vb
//
// sonoshape_viewer_publisher (bench/viewer_publisher.cpp) publishes three spheres of N triangles
// each, one update every interval, each update's timestamp_s the wall clock when published;
// `sonoshape view` relays them to the page, which notes the wall clock once each mesh is drawn
// and the picture finished (window.sonoshapeViewer.drawLog). Then the page orbits the largest
// surfaces, finishing every picture, for --fps-seconds (window.sonoshapeViewer.measureFps).
// Prints a table and writes WORK_DIR/viewer_bench.json.
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { findChromium, launchChromium, openPage } from '../tests/browser/chromium.mjs';

const [sonoshape, publisherBinary, workDir, ...rest] = process.argv.slice(2);
const option = (name, fallback) => {
  const at = rest.indexOf(name);
  return at >= 0 ? rest[at + 1] : fallback;
};
const sizes = option('--sizes', '20000,200000').split(',').map(Number);
const updates = Number(option('--updates', '10'));
const intervals = option('--interval-ms', '1000,4000').split(',').map(Number);
const fpsSeconds = Number(option('--fps-seconds', '5'));
const kWidth = 1200;
const kHeight = 800;
const children = [];
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

function fail(reason) {
  console.error('FAILED: ' + reason);
  for (const child of children) child.kill('SIGKILL');
  process.exit(1);
}

function start(command, args) {
  const child = spawn(command, args, { stdio: ['ignore', 'pipe', 'pipe'] });
  children.push(child);
  let output = '';
  child.stdout.on('data', (d) => { output += d; });
  child.stderr.on('data', (d) => { output += d; });
  child.output = () => output;
  child.exited = new Promise((resolve) => child.on('exit', (code) => resolve(code)));
  return child;
}

async function waitFor(child, pattern, timeoutMs) {
  const deadline = Date.now() + timeoutMs;
  while (Date.now() < deadline) {
    const match = child.output().match(pattern);
    if (match) return match;
    await sleep(50);
  }
  fail('no ' + pattern + ' in ' + timeoutMs + ' ms:\n' + child.output());
}

function percentile(sorted, p) {
  // nearest rank
  return sorted[Math.min(sorted.length - 1, Math.floor((p / 100) * sorted.length))];
}

async function main() {
  if (!sonoshape || !publisherBinary || !workDir)
    fail('usage: viewer_bench.mjs SONOSHAPE SONOSHAPE_VIEWER_PUBLISHER WORK_DIR [options]');
  const chromium = findChromium();
  if (!chromium) fail('chromium is not installed (scripts/install-deps installs it)');
  fs.rmSync(workDir, { recursive: true, force: true });
  fs.mkdirSync(workDir, { recursive: true });
  const endpoint = 'tcp://127.0.0.1:' + (20000 + Math.floor(Math.random() * 20000));
  const view = start(sonoshape, ['view', endpoint, '--no-snapshot', '--http', '127.0.0.1:0']);
  const [, url] = await waitFor(view, /open (http:\/\/127\.0\.0\.1:\d+\/)/, 20000);
  const { browser, send } = launchChromium(chromium, { width: kWidth, height: kHeight,
                                                        userDataDir: path.join(workDir, 'chromium') });
  children.push(browser);
  const { sessionId, evaluate } = await openPage(send, url, kWidth, kHeight);
  for (let i = 0; i < 100 && !(await evaluate('!!window.sonoshapeViewer')); ++i) await sleep(100);

  const results = { chromium: (await send('Browser.getVersion')).product,
                    gpu: await evaluate('window.sonoshapeViewer.gpu'), runs: [] };
  for (const [k, size] of sizes.entries()) {
    const intervalMs = intervals[Math.min(k, intervals.length - 1)];
    await evaluate('window.sonoshapeViewer.drawLog = []');
    const publisher = start(publisherBinary, [endpoint, String(size), String(updates),
                                              String(intervalMs), '1500']);
    if ((await publisher.exited) !== 0) fail('the publisher failed:\n' + publisher.output());
    await sleep(Math.max(2000, intervalMs));  // the last meshes drawn
    const log = await evaluate('window.sonoshapeViewer.drawLog');
    const triangles = Number(publisher.output().match(/labels of (\d+) triangles/)[1]);
    const stats = (values) => {
      const sorted = [...values].sort((a, b) => a - b);
      return { p50: percentile(sorted, 50), p95: percentile(sorted, 95), max: sorted[sorted.length - 1] };
    };
    if (!log.length) fail(`no mesh of ${size} triangles was drawn:\n${view.output()}`);
    const run = {
      triangles_per_label: triangles, updates, interval_ms: intervalMs,
      meshes_published: 3 * updates, meshes_drawn: log.length,
      // Published to drawn; split into published to received by the page (relay, WebSocket)
      // and received to drawn (decoding, geometry, the picture finished).
      latency_ms: stats(log.map((e) => e.drawn_ms - 1000 * e.timestamp_s)),
      transport_ms: stats(log.map((e) => e.received_ms - 1000 * e.timestamp_s)),
      page_ms: stats(log.map((e) => e.drawn_ms - e.received_ms)),
    };
    results.runs.push(run);
    const show = (s) => `p50 ${s.p50.toFixed(0)}, p95 ${s.p95.toFixed(0)}, max ${s.max.toFixed(0)} ms`;
    console.log(`3 x ${triangles} triangles, every ${intervalMs} ms: ${run.meshes_drawn} of ` +
                `${run.meshes_published} meshes drawn; published to drawn ${show(run.latency_ms)} ` +
                `(to the page ${show(run.transport_ms)}; in the page ${show(run.page_ms)})`);
  }
  await evaluate('window.sonoshapeViewer.drawLog = null');
  const fps = await evaluate(`window.sonoshapeViewer.measureFps(${fpsSeconds})`);
  results.fps = { triangles: 3 * results.runs[results.runs.length - 1].triangles_per_label, ...fps };
  console.log(`frame rate orbiting 3 x ${results.runs[results.runs.length - 1].triangles_per_label} ` +
              `triangles: ${fps.fps.toFixed(1)} fps (${fps.frames} frames in ${fps.seconds.toFixed(1)} s)`);
  const { data } = await send('Page.captureScreenshot', { format: 'png' }, sessionId);
  fs.writeFileSync(path.join(workDir, 'page.png'), Buffer.from(data, 'base64'));
  fs.writeFileSync(path.join(workDir, 'viewer_bench.json'), JSON.stringify(results, null, 2) + '\n');
  console.log(`${results.chromium}, WebGL on ${results.gpu.name} (antialias ` +
              `${results.gpu.antialias}); results in ${path.join(workDir, 'viewer_bench.json')}`);
  for (const child of children) child.kill('SIGTERM');
  process.exit(0);
}

main().catch((e) => fail(e.stack || String(e)));
