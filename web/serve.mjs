#!/usr/bin/env node
// A small static server for web/viewer.html: the repository at /, the HDRI data cache at /hdri/
// ($CLOTHFIT_DATA/hdri or ~/.cache/clothfit/hdri; /hdri/index.json lists the names), 127.0.0.1 only.
//   node web/serve.mjs [--port 8000]   then open http://127.0.0.1:8000/web/viewer.html
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
  const server = http.createServer((req, res) => {
    const url = new URL(req.url, 'http://127.0.0.1');
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
    const rel = path.normalize(decodeURIComponent(url.pathname));
    let file;
    if (rel.startsWith('/fs/') && roots.length) {
      file = rel.slice(3);
      if (!roots.some((r) => file === r || file.startsWith(r + path.sep))) { res.statusCode = 403; res.end(); return; }
      if (!fs.existsSync(file) || fs.statSync(file).isDirectory()) { res.statusCode = 404; res.end(); return; }
      res.setHeader('Content-Type', MIME[path.extname(file)] ?? 'application/octet-stream');
      fs.createReadStream(file).pipe(res);
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
    if (!file.startsWith(repoRoot + path.sep) && !file.startsWith(hdriDir + path.sep)) { res.statusCode = 403; res.end(); return; }
    if (!fs.existsSync(file) || fs.statSync(file).isDirectory()) { res.statusCode = 404; res.end(); return; }
    res.setHeader('Content-Type', MIME[path.extname(file)] ?? 'application/octet-stream');
    fs.createReadStream(file).pipe(res);
  });
  return new Promise((resolve) => server.listen(port, '127.0.0.1', () => resolve(server)));
}

if (process.argv[1] && fileURLToPath(import.meta.url) === path.resolve(process.argv[1])) {
  const i = process.argv.indexOf('--port');
  const server = await startServer({ port: i > 0 ? Number(process.argv[i + 1]) : 8000 });
  console.log(`clothfit viewer: http://127.0.0.1:${server.address().port}/web/viewer.html`);
}
