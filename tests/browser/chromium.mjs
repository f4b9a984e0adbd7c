// Debian's chromium, headless with software WebGL, driven over its DevTools protocol on a pipe
// (--remote-debugging-pipe): fd 3 takes commands, fd 4 gives replies, NUL-separated JSON. Only
// node's own modules. Used by tests/browser/viewer_e2e.mjs and bench/viewer_bench.mjs.
import { spawn, spawnSync } from 'node:child_process';

/** The chromium command on PATH, or null. */
export function findChromium() {
  for (const name of ['chromium', 'chromium-browser', 'google-chrome']) {
    const found = spawnSync('sh', ['-c', 'command -v ' + name], { encoding: 'utf8' });
    if (found.status === 0) return found.stdout.trim();
  }
  return null;
}

/**
 * Starts chromium headless on about:blank.
 * @returns {{browser: import('node:child_process').ChildProcess, send: Function}} `send(method,
 *   params, sessionId)` resolves with the command's result or rejects with its error
 */
export function launchChromium(chromium, { width, height, userDataDir }) {
  const browser = spawn(chromium, [
    '--headless', '--no-sandbox', '--remote-debugging-pipe', '--use-angle=swiftshader',
    '--enable-unsafe-swiftshader', '--no-first-run', '--disable-extensions',
    `--window-size=${width},${height}`, '--user-data-dir=' + userDataDir, 'about:blank',
  ], { stdio: ['ignore', 'ignore', 'ignore', 'pipe', 'pipe'] });
  const pending = new Map();
  let nextId = 1;
  let buffer = '';
  browser.stdio[4].on('data', (data) => {
    buffer += data.toString('utf8');
    let end;
    while ((end = buffer.indexOf('\0')) >= 0) {
      const message = JSON.parse(buffer.slice(0, end));
      buffer = buffer.slice(end + 1);
      const waiter = pending.get(message.id);
      if (!waiter) continue;
      pending.delete(message.id);
      if (message.error) waiter.reject(new Error(JSON.stringify(message.error)));
      else waiter.resolve(message.result);
    }
  });
  const send = (method, params = {}, sessionId = undefined) => new Promise((resolve, reject) => {
    const id = nextId++;
    pending.set(id, { resolve, reject });
    browser.stdio[3].write(JSON.stringify({ id, method, params, sessionId }) + '\0');
  });
  return { browser, send };
}

/**
 * Opens `url` in chromium's page at width x height CSS pixels (scale 1).
 * @returns {Promise<{sessionId: string, evaluate: Function}>} `evaluate(expression)` resolves with
 *   the expression's value (awaited when it is a promise), returned by value
 */
export async function openPage(send, url, width, height) {
  const { targetInfos } = await send('Target.getTargets');
  const page = targetInfos.find((t) => t.type === 'page');
  if (!page) throw new Error('chromium opened no page');
  const { sessionId } = await send('Target.attachToTarget', { targetId: page.targetId, flatten: true });
  await send('Emulation.setDeviceMetricsOverride', { width, height, deviceScaleFactor: 1, mobile: false },
             sessionId);
  await send('Page.navigate', { url }, sessionId);
  const evaluate = async (expression) => (await send('Runtime.evaluate',
    { expression, returnByValue: true, awaitPromise: true }, sessionId)).result.value;
  return { sessionId, evaluate };
}
