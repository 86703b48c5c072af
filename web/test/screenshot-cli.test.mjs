// Node test of web/tools/screenshot.mjs's command line (session 27 audit): --help prints the
// usage and exits 0 without starting a server or a browser and without writing viewer.png (it
// used to ignore the flag and take a screenshot into the current directory); an unknown option,
// a missing value, a bad --timeout or a missing --chromium is an error (exit 2) naming it, again
// with nothing written. Runs in an empty temporary directory; no browser is needed.
// Usage: node web/test/screenshot-cli.test.mjs   (exits non-zero on a failure)
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const tool = path.join(here, '..', 'tools', 'screenshot.mjs');
const cwd = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-shot-cli-'));
let checks = 0;
const check = (ok, what) => { assert.ok(ok, what); checks++; };
// A wrong tool would start Chromium: the timeout keeps this test short either way.
const run = (...a) => spawnSync(process.execPath, [tool, ...a], { cwd, encoding: 'utf8', timeout: 20000 });
try {
  for (const h of ['--help', '-h']) {
    const r = run(h);
    check(r.status === 0, `${h}: exit ${r.status} (${r.signal ?? ''}), expected 0`);
    check(/^Usage: node web\/tools\/screenshot\.mjs/.test(r.stdout) && /--out FILE/.test(r.stdout) && /--query/.test(r.stdout), `${h}: prints the usage (${JSON.stringify(r.stdout.slice(0, 80))})`);
    check(fs.readdirSync(cwd).length === 0, `${h}: nothing written (${fs.readdirSync(cwd).join(', ')})`);
  }
  // --help wins wherever it stands, before the other options are looked at
  check(run('--out', 'x.png', '--help').status === 0 && !fs.existsSync(path.join(cwd, 'x.png')), '--help after other options');
  const bad = [
    [['--bogus'], /unknown option "--bogus"/],
    [['stray'], /unknown argument "stray"/],
    [['--out'], /--out: expected a value/],
    [['--out', '--query', 'a=b'], /--out: expected a value/],
    [['--timeout', 'soon'], /--timeout: expected a number of seconds > 0, got "soon"/],
    [['--timeout', '0'], /--timeout: .*got "0"/],
    [['--timeout=-5'], /--timeout: .*got "-5"/],
    [['--chromium', path.join(cwd, 'no-such-browser')], /--chromium: ".*no-such-browser" not found/],
  ];
  for (const [a, re] of bad) {
    const r = run(...a);
    check(r.status === 2, `${a.join(' ')}: exit ${r.status} (${r.signal ?? ''}), expected 2`);
    check(re.test(r.stderr) && !/\n\s+at /.test(r.stderr), `${a.join(' ')}: ${JSON.stringify(r.stderr.split('\n')[0])}`);
    check(fs.readdirSync(cwd).length === 0, `${a.join(' ')}: nothing written`);
  }
} finally {
  fs.rmSync(cwd, { recursive: true, force: true });
}
console.log(`screenshot-cli: ${checks} checks passed`);
