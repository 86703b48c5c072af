#!/usr/bin/env node
// A small static server for web/viewer.html: the repository at /, the HDRI data cache at /hdri/
// ($CLOTHFIT_DATA/hdri or ~/.cache/clothfit/hdri; /hdri/index.json lists the names), 127.0.0.1 only.
//   node web/serve.mjs [--port 8000]   then open http://127.0.0.1:8000/web/viewer.html
// A malformed path ('/%') is a 400, a '..' segment after decoding a 403; a busy port is one line
// naming it (choose another with --port). Test: web/test/serve.test.mjs.
// POST /shot (a PNG body) is accepted only when started with onShot (web/tools/screenshot.mjs).
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

export const repoRoot = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..');
export const hdriDir = path.join(process.env.CLOTHFIT_DATA || path.join(os.homedir(), '.cache', 'clothfit'), 'hdri');
const MIME = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.json': 'application/json', '.png': 'image/png', '.css': 'text/css' };

// Options: port (0: ephemeral); onShot(body) for POST /shot; onLog(text) for POST /log;
// onPost(url, body) for any other POST (the browser test's /result and /done); fsRoots: absolute
// directories also served as GET /fs/<absolute path> (the browser test's work dir and data);
// a path is served only if it lies under one of them (checked on the URL-normalised path, so
// symlinked entries of a root are followed).
export function startServer({ port = 0, onShot = null, onLog = null, onPost = null, fsRoots = [] } = {}) {
  const roots = fsRoots.flatMap((r) => [r, fs.realpathSync(r)]);
  // A refused request: a status and a short plain-text reason (never the request's own text).
  const refuse = (res, status, why) => {
    if (!res.headersSent) {
      res.statusCode = status;
      res.setHeader('Content-Type', 'text/plain; charset=utf-8');
    }
    res.end(`${status} ${why}\n`);
  };
  const sendFile = (res, file) => {
    res.setHeader('Content-Type', MIME[path.extname(file)] ?? 'application/octet-stream');
    const stream = fs.createReadStream(file);
    // an unreadable file (EACCES) or one removed meanwhile: answered, not an unhandled 'error'
    stream.on('error', (e) => refuse(res, e.code === 'EACCES' ? 403 : 500, e.code === 'EACCES' ? 'forbidden' : 'read error'));
    stream.pipe(res);
  };
  const handle = (req, res) => {
    let url;
    try {
      url = new URL(req.url, 'http://127.0.0.1');
    } catch {
      refuse(res, 400, 'bad request: malformed URL');
      return;
    }
    if (req.method === 'POST') {
      const chunks = [];
      req.on('data', (d) => chunks.push(d));
      req.on('end', () => {
        const body = Buffer.concat(chunks);
        if (url.pathname === '/shot' && onShot) onShot(body);
        else if (url.pathname === '/log' && onLog) onLog(body.toString());
        else if (onPost) onPost(url, body);
        res.end('ok');
      });
      return;
    }
    // The path is decoded once, here: a malformed escape ('/%', '/%zz') is a 400, not an
    // exception; a NUL is refused; a '..' segment that survived URL normalisation (an encoded
    // slash: '/web/..%2f..%2fetc') is refused before any file name is built.
    let decoded;
    try {
      decoded = decodeURIComponent(url.pathname);
    } catch {
      refuse(res, 400, 'bad request: malformed percent-encoding in the path');
      return;
    }
    if (decoded.includes('\0')) { refuse(res, 400, 'bad request: NUL in the path'); return; }
    if (decoded.split('/').includes('..')) { refuse(res, 403, 'forbidden: ".." in the path'); return; }
    const rel = path.normalize(decoded);
    let file;
    if (rel.startsWith('/fs/') && roots.length) {
      file = rel.slice(3);
      if (!roots.some((r) => file === r || file.startsWith(r + path.sep))) { refuse(res, 403, 'forbidden'); return; }
      if (!fs.existsSync(file) || fs.statSync(file).isDirectory()) { refuse(res, 404, 'not found'); return; }
      sendFile(res, file);
      return;
    }
    if (rel === '/hdri/index.json') {
      const names = fs.existsSync(hdriDir) ? fs.readdirSync(hdriDir).filter((f) => /\.(exr|hdr)$/.test(f)).map((f) => f.replace(/\.(exr|hdr)$/, '')).sort() : [];
      res.setHeader('Content-Type', 'application/json');
      res.end(JSON.stringify(names));
      return;
    }
    if (rel.startsWith('/hdri/')) file = path.join(hdriDir, rel.slice(6));
    else file = path.join(repoRoot, rel);
    if (!file.startsWith(repoRoot + path.sep) && !file.startsWith(hdriDir + path.sep)) { refuse(res, 403, 'forbidden'); return; }
    if (!fs.existsSync(file) || fs.statSync(file).isDirectory()) { refuse(res, 404, 'not found'); return; }
    sendFile(res, file);
  };
  const server = http.createServer((req, res) => {
    // Only requests addressed to this machine by name or loopback address (a page elsewhere
    // that re-binds its own host name to 127.0.0.1 sends its own Host: refused, so it cannot
    // read the repository or a --root directory through the browser).
    const host = req.headers.host;
    if (host !== undefined && !/^(127\.0\.0\.1|localhost|\[::1\])(:\d+)?$/i.test(host)) { res.statusCode = 403; res.end(); return; }
    try {
      handle(req, res);
    } catch (e) {  // anything else: a 500 for this request, the server goes on
      console.error(`web/serve.mjs: ${req.method} request failed: ${e.message}`);
      refuse(res, 500, 'internal error');
    }
  });
  // Rejects on a listen error (EADDRINUSE, EACCES) instead of an unhandled 'error' event.
  return new Promise((resolve, reject) => {
    server.once('error', reject);
    server.listen(port, '127.0.0.1', () => {
      server.removeListener('error', reject);
      resolve(server);
    });
  });
}

const USAGE = `Usage: node web/serve.mjs [--port N] [--root DIR]...
Serves the repository at / and the HDRI data cache at /hdri/ on 127.0.0.1 (default port 8000;
--port 0 picks a free one), then open http://127.0.0.1:PORT/web/viewer.html (docs/web.md).
--root DIR also serves the directory DIR (e.g. presets fitted outside the repository) as
/fs/<absolute path of DIR>/...; clothfit report's viewer links name the --root they need.`;

if (process.argv[1] && fileURLToPath(import.meta.url) === path.resolve(process.argv[1])) {
  const argv = process.argv.slice(2);
  let port = 8000;
  const fsRoots = [];
  for (let i = 0; i < argv.length; ++i) {
    const a = argv[i];
    if (a === '--help' || a === '-h') { console.log(USAGE); process.exit(0); }
    if (a === '--root' || a.startsWith('--root=')) {
      const v = a === '--root' ? argv[++i] : a.slice(7);
      let dir = null;
      try { dir = v !== undefined && v !== '' ? fs.realpathSync(path.resolve(v)) : null; } catch { dir = null; }
      if (!dir || !fs.statSync(dir).isDirectory()) {
        console.error(`web/serve.mjs: --root: expected an existing directory, got ${v === undefined ? 'nothing' : JSON.stringify(v)}`);
        process.exit(2);
      }
      fsRoots.push(path.resolve(v));  // startServer adds its real path too
      continue;
    }
    if (a === '--port' || a.startsWith('--port=')) {
      const v = a === '--port' ? argv[++i] : a.slice(7);
      if (v === undefined || !/^\d+$/.test(v) || Number(v) > 65535) {
        console.error(`web/serve.mjs: --port: expected an integer in [0, 65535], got ${v === undefined ? 'nothing' : JSON.stringify(v)}`);
        process.exit(2);
      }
      port = Number(v);
    } else {
      console.error(`web/serve.mjs: unknown option ${JSON.stringify(a)}\n${USAGE}`);
      process.exit(2);
    }
  }
  let server;
  try {
    server = await startServer({ port, fsRoots });
  } catch (e) {
    if (e.code === 'EADDRINUSE') console.error(`web/serve.mjs: port ${port} is already in use (another web/serve.mjs?); choose another with --port N, or --port 0 for a free one`);
    else if (e.code === 'EACCES') console.error(`web/serve.mjs: port ${port} needs privileges to listen on; choose a port above 1023 with --port N, or --port 0 for a free one`);
    else console.error(`web/serve.mjs: cannot listen on 127.0.0.1:${port}: ${e.message}`);
    process.exit(1);
  }
  console.log(`clothfit viewer: http://127.0.0.1:${server.address().port}/web/viewer.html`);
  for (const r of fsRoots) console.log(`  also serving ${r} as /fs${r}/`);
}
