// Node test of web/serve.mjs (session 27 audit): bad requests are answered, not fatal.
//   - a malformed percent-encoding ('/%', '/%zz', a cut UTF-8 sequence) is a 400 (it was an
//     uncaught URIError that killed the server), and the server still serves afterwards;
//   - path traversal, plain ('/../../etc/passwd'), dot-encoded ('/%2e%2e/...') or slash-encoded
//     ('/web/..%2f..%2f...', also under /hdri/ and /fs/) never serves a file outside the roots;
//   - the command line: a busy port is one line naming the port and --port (no stack trace),
//     a bad --port value or unknown option is refused naming it, --help prints the usage.
// Usage: node web/test/serve.test.mjs   (exits non-zero on a failure)
import assert from 'node:assert/strict';
import { spawn, spawnSync } from 'node:child_process';
import fs from 'node:fs';
import net from 'node:net';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { startServer } from '../serve.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const serveMjs = path.join(here, '..', 'serve.mjs');
let checks = 0;
const check = (ok, what) => { assert.ok(ok, what); checks++; };

// One raw HTTP/1.0 request (the path sent byte for byte, as curl or a hostile client would):
// resolves {status, body}; status 0 if the connection closed without an answer.
function rawGet(port, target) {
  return new Promise((resolve, reject) => {
    const sock = net.connect(port, '127.0.0.1', () => sock.write(`GET ${target} HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n`));
    const chunks = [];
    sock.on('data', (d) => chunks.push(d));
    sock.on('error', reject);
    sock.on('close', () => {
      const text = Buffer.concat(chunks).toString('latin1');
      const m = /^HTTP\/1\.[01] (\d{3})/.exec(text);
      resolve({ status: m ? Number(m[1]) : 0, body: text.slice(text.indexOf('\r\n\r\n') + 4) });
    });
    sock.setTimeout(5000, () => sock.destroy());
  });
}

const work = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-serve-test-'));
const allowed = path.join(work, 'allowed');
fs.mkdirSync(allowed);
fs.writeFileSync(path.join(allowed, 'ok.txt'), 'inside');
fs.writeFileSync(path.join(work, 'secret.txt'), 'outside');
const server = await startServer({ fsRoots: [allowed] });
const { port } = server.address();
try {
  check((await rawGet(port, '/web/viewer.html')).status === 200, 'serves the viewer');
  for (const bad of ['/%', '/%zz', '/web/%E0%A4%A', '/web/viewer.html%', '/hdri/%']) {
    const r = await rawGet(port, bad);
    check(r.status === 400, `${bad}: status ${r.status}, expected 400`);
    check(!r.body.includes('URIError') && !/\n\s+at /.test(r.body), `${bad}: no stack trace in the answer`);
  }
  // traversal: never 200, never the file's text
  const traversal = ['/../../etc/passwd', '/%2e%2e/%2e%2e/etc/passwd', '/web/..%2f..%2f..%2f..%2f..%2fetc%2fpasswd',
    '/web/%2e%2e%2f%2e%2e%2f%2e%2e%2f%2e%2e%2fetc%2fpasswd', '/hdri/..%2f..%2f..%2f..%2fetc%2fpasswd',
    `/fs${allowed}/..%2fsecret.txt`, `/fs${allowed}/%2e%2e/secret.txt`, `/fs${work}/secret.txt`, '/web/viewer.html%00.png'];
  for (const t of traversal) {
    const r = await rawGet(port, t);
    check(r.status >= 400 && r.status < 500, `${t}: status ${r.status}, expected a 4xx`);
    check(!r.body.includes('root:') && !r.body.includes('outside'), `${t}: no file from outside the roots`);
  }
  check((await rawGet(port, '/web/..%2fREADME.md')).status === 403, 'an encoded-slash ".." segment is refused (403)');
  const inside = await rawGet(port, `/fs${allowed}/ok.txt`);
  check(inside.status === 200 && inside.body === 'inside', `/fs/ still serves inside its root (${inside.status})`);
  check((await rawGet(port, '/web/serve.mjs')).status === 200, 'still serving after the bad requests');
  // another Host (DNS rebinding) is refused; the loopback names are served
  const rebound = await new Promise((resolve, reject) => {
    const sock = net.connect(port, '127.0.0.1', () => sock.write('GET /web/viewer.html HTTP/1.0\r\nHost: evil.example:8000\r\n\r\n'));
    let t = ''; sock.on('data', (d) => { t += d; }); sock.on('error', reject);
    sock.on('close', () => resolve(Number((/^HTTP\/1\.[01] (\d{3})/.exec(t) || [0, 0])[1])));
  });
  check(rebound === 403, `Host evil.example: status ${rebound}, expected 403`);

  // the command line, on the port this server holds
  const run = (...a) => spawnSync(process.execPath, [serveMjs, ...a], { encoding: 'utf8', timeout: 20000 });
  const busy = run('--port', String(port));
  check(busy.status === 1, `busy port: exit ${busy.status}, expected 1`);
  const lines = busy.stderr.trim().split('\n');
  check(lines.length === 1 && lines[0].includes(`port ${port} is already in use`) && lines[0].includes('--port'), `busy port: one line naming the port and --port (${JSON.stringify(busy.stderr)})`);
  for (const [a, re] of [[['--port', 'abc'], /--port: expected an integer in \[0, 65535\], got "abc"/], [['--port', '70000'], /--port: .*"70000"/],
    [['--port'], /--port: .*got nothing/], [['--bogus'], /unknown option "--bogus"/]]) {
    const r = run(...a);
    check(r.status === 2 && re.test(r.stderr) && !/\n\s+at /.test(r.stderr), `${a.join(' ')}: exit ${r.status}, ${JSON.stringify(r.stderr)}`);
  }
  const help = run('--help');
  check(help.status === 0 && /^Usage: node web\/serve\.mjs/.test(help.stdout), `--help: exit ${help.status}`);
  // --root DIR (session 27; clothfit report's viewer links name it): DIR served as /fs/<DIR>/,
  // nothing beside it; a missing directory refused
  const bad = run('--root', path.join(work, 'nope'));
  check(bad.status === 2 && /--root: expected an existing directory/.test(bad.stderr), `--root missing: exit ${bad.status}, ${JSON.stringify(bad.stderr)}`);
  const child = spawn(process.execPath, [serveMjs, '--port', '0', '--root', allowed], { stdio: ['ignore', 'pipe', 'pipe'] });
  try {
    const rootPort = await new Promise((resolve, reject) => {
      let out = '';
      child.stdout.on('data', (d) => { out += d; const m = /127\.0\.0\.1:(\d+)\//.exec(out); if (m) resolve(Number(m[1])); });
      child.on('exit', (c) => reject(new Error(`serve.mjs --root exited ${c}`)));
      setTimeout(() => reject(new Error('serve.mjs --root: no address printed')), 15000);
    });
    const ok = await rawGet(rootPort, `/fs${allowed}/ok.txt`);
    check(ok.status === 200 && ok.body === 'inside', `--root: a file inside is served (${ok.status})`);
    check((await rawGet(rootPort, `/fs${work}/secret.txt`)).status === 403, '--root: a file beside the root is refused');
  } finally {
    child.kill();
  }
} finally {
  server.close();
  fs.rmSync(work, { recursive: true, force: true });
}
console.log(`serve: ${checks} checks passed`);
