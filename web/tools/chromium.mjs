// Stopping a headless Chromium started by the project's tools (web/tools/screenshot.mjs,
// tests/browser/run.mjs). Spawn it with { detached: true } so that it leads its own process
// group: the zygote, renderer and GPU processes keep writing the --user-data-dir profile for a
// moment after the main process exits, so the profile can only be removed once the whole group
// is gone (removing it right after SIGTERM failed with ENOTEMPTY and left ~1 MB in /tmp per run).
import fs from 'node:fs';

const sleep = (ms) => new Promise((r) => { setTimeout(r, ms); });

function groupAlive(pid) {
  try { process.kill(-pid, 0); return true; } catch { return false; }
}

// SIGTERM to the group, wait up to `waitMs` for it to go (SIGKILL after that), then remove
// `profile`. Returns a warning string, or '' when everything was cleaned up.
export async function stopChromium(browser, profile, waitMs = 10000) {
  if (browser.pid !== undefined) {
    try { process.kill(-browser.pid, 'SIGTERM'); } catch { browser.kill('SIGTERM'); }
    const t0 = Date.now();
    while (groupAlive(browser.pid) && Date.now() - t0 < waitMs) await sleep(50);
    if (groupAlive(browser.pid)) {
      try { process.kill(-browser.pid, 'SIGKILL'); } catch { /* gone meanwhile */ }
      await sleep(200);
    }
  }
  try {
    fs.rmSync(profile, { recursive: true, force: true, maxRetries: 5, retryDelay: 200 });
  } catch (e) {
    return `could not remove the browser profile ${profile}: ${e.code}`;
  }
  return '';
}

// A detached browser does not get the terminal's SIGINT and outlives an early process.exit():
// kill its group when this process exits or is interrupted.
export function killChromiumOnExit(browser) {
  const kill = () => { try { process.kill(-browser.pid, 'SIGKILL'); } catch { /* already gone */ } };
  process.on('exit', kill);
  for (const sig of ['SIGINT', 'SIGTERM']) {
    process.once(sig, () => { kill(); process.exit(128 + (sig === 'SIGINT' ? 2 : 15)); });
  }
}
