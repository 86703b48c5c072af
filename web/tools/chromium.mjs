// Stopping a headless Chromium started by the project's tools (web/tools/screenshot.mjs,
// tests/browser/run.mjs). Spawn it with { detached: true } so that it leads its own process
// group: the zygote, renderer and GPU processes keep writing the --user-data-dir profile for a
// moment after the main process exits, so the profile can only be removed once the whole group
// is gone (removing it right after SIGTERM failed with ENOTEMPTY and left ~1 MB in /tmp per run).
//
// Signals go to the group (-pid) only while it may still be ours: from the moment the group is
// seen empty (or the main process has exited and the group is empty), nothing is sent, so a
// process group id reused by the system is never signalled.
import { spawn } from 'node:child_process';
import fs from 'node:fs';

// Starts headless Chromium on `url` with SwiftShader WebGL2 (the flags of the browser test and
// the GPU audit), in its own process group, stderr piped; killChromiumOnExit is armed.
export function spawnHeadlessChromium(chromium, url, profile, { windowSize = '512,512' } = {}) {
  const browser = spawn(chromium, [
    '--headless=new', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-sandbox',
    '--disable-gpu-sandbox', '--no-first-run', '--no-default-browser-check', '--disable-extensions',
    '--disable-background-networking', '--mute-audio', '--log-level=3', `--user-data-dir=${profile}`,
    `--window-size=${windowSize}`, url,
  ], { stdio: ['ignore', 'ignore', 'pipe'], detached: true });  // own group: see above
  killChromiumOnExit(browser, profile);
  return browser;
}

const sleep = (ms) => new Promise((r) => { setTimeout(r, ms); });

function groupAlive(pid) {
  try { process.kill(-pid, 0); return true; } catch { return false; }
}

const state = new WeakMap();  // browser -> { gone, detach }

function signalGroup(browser, sig) {
  const s = state.get(browser);
  if (s?.gone || browser.pid === undefined) return;
  if (!groupAlive(browser.pid)) { if (s) s.gone = true; return; }
  try { process.kill(-browser.pid, sig); } catch { /* gone meanwhile */ }
}

// Kills the browser's group when this process exits or is interrupted (a detached browser does
// not get the terminal's SIGINT and would outlive an early process.exit()). On SIGINT / SIGTERM
// the profile is removed best-effort and the signal is re-raised, so the caller sees this process
// die by that signal, as it would without the handler.
export function killChromiumOnExit(browser, profile) {
  const s = { gone: false, detach: () => {} };
  state.set(browser, s);
  const onExit = () => signalGroup(browser, 'SIGKILL');
  const onSignal = (sig) => {
    s.detach();
    signalGroup(browser, 'SIGKILL');
    if (profile) { try { fs.rmSync(profile, { recursive: true, force: true }); } catch { /* best effort */ } }
    process.kill(process.pid, sig);
  };
  process.on('exit', onExit);
  process.on('SIGINT', onSignal);
  process.on('SIGTERM', onSignal);
  s.detach = () => {
    process.removeListener('exit', onExit);
    process.removeListener('SIGINT', onSignal);
    process.removeListener('SIGTERM', onSignal);
  };
  browser.once('exit', () => { if (browser.pid !== undefined && !groupAlive(browser.pid)) s.gone = true; });
}

// SIGTERM to the group, wait up to `waitMs` for it to go (SIGKILL after that), then remove
// `profile` and the exit handlers. Returns a warning string, or '' when everything was cleaned up.
export async function stopChromium(browser, profile, waitMs = 10000) {
  if (browser.pid !== undefined) {
    signalGroup(browser, 'SIGTERM');
    const t0 = Date.now();
    while (groupAlive(browser.pid) && Date.now() - t0 < waitMs) await sleep(50);
    if (groupAlive(browser.pid)) {
      signalGroup(browser, 'SIGKILL');
      await sleep(200);
    }
    const s = state.get(browser);
    if (s && !groupAlive(browser.pid)) { s.gone = true; s.detach(); }
  }
  try {
    fs.rmSync(profile, { recursive: true, force: true, maxRetries: 5, retryDelay: 200 });
  } catch (e) {
    return `could not remove the browser profile ${profile}: ${e.code}`;
  }
  return '';
}
