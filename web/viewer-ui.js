// The DOM side of web/viewer.html that takes untrusted text (session 27 audit), kept free of
// three.js so that node can test it with a small DOM stand-in (web/test/viewer.test.mjs):
// query-string values, file names, preset contents and error messages reach the page only as
// text nodes (textContent, option.value), never as markup.

/** Fills a <select> with one <option> per value (value and label as text), `current` selected. */
export function fillSelect(select, values, current, label = (v) => v) {
  const list = values.includes(current) ? values : [current, ...values];
  const doc = select.ownerDocument ?? globalThis.document;
  select.replaceChildren(...list.map((v) => {
    const o = doc.createElement('option');
    o.value = v;
    o.textContent = label(v);
    o.selected = v === current;
    return o;
  }));
}

/** The message of an error, without its stack (the stack goes to the console). */
export function errorText(e) {
  if (e instanceof Error) return e.message || e.name;
  if (e !== null && typeof e === 'object' && typeof e.type === 'string') return `${e.type} event${e.target?.src ? ` for ${e.target.src}` : ''}`;
  return String(e);
}

/**
 * Shows an error in the page's error panel (as text, the message only, prefixed by `context`,
 * e.g. the file name) and the whole error, stack included, on the console. Returns the text.
 */
export function showError(panel, e, context = '') {
  const text = `${context ? `${context}: ` : ''}${errorText(e)}`;
  console.error(context ? `viewer: ${context}:` : 'viewer:', e);
  panel.textContent = `error: ${text}`;
  panel.hidden = false;
  return text;
}

export function clearError(panel) {
  panel.textContent = '';
  panel.hidden = true;
}

/**
 * ?shadows=: 1 / true (three.js shadow maps with web/clothfit.js's SHADOW_DEFAULTS), 0 / false
 * (off), a JSON object of shadow settings, or absent (null: the card's visibility.shadows).
 */
export function parseShadowsParam(s) {
  if (s === null || s === undefined) return undefined;
  if (s === '1' || s === 'true') return true;
  if (s === '0' || s === 'false') return false;
  const expected = 'expected 1, 0, true, false or a JSON object of shadow settings, e.g. shadows={"type":"pcf","mapSize":4096} (docs/web.md)';
  let v;
  try {
    v = JSON.parse(s);
  } catch (e) {
    throw new Error(`shadows=${JSON.stringify(s.slice(0, 200))}: not JSON (${e.message}); ${expected}`);
  }
  if (v === null || typeof v !== 'object' || Array.isArray(v)) throw new Error(`shadows=${JSON.stringify(s.slice(0, 200))}: ${expected}`);
  return v;
}

/** ?units=N: a whole number of texture units >= 1, or absent (null). */
export function parseUnitsParam(s) {
  if (s === null || s === undefined) return null;
  if (!/^\s*\d+\s*$/.test(s) || Number(s) < 1) throw new Error(`units=${JSON.stringify(s.slice(0, 200))}: expected a whole number of texture units >= 1, e.g. units=16 (docs/web.md "Real GPUs")`);
  return Number(s);
}

/**
 * What a preset opened with the file picker cannot bring along: its weave maps (a clothfit preset's
 * "weave_maps") and its textures (three.js JSON "images"), which are files next to it that a local
 * file cannot fetch. Lines for the info panel (empty if nothing is missing).
 */
export function localFileNotes(json, fileName) {
  const notes = [];
  const how = 'serve the preset\'s folder (node web/serve.mjs serves the repository; a preset elsewhere: copy it with its files under the repository) and open viewer.html?preset=<its URL>';
  const wm = json?.weave_maps;
  if (wm !== undefined && wm !== null) {
    const named = typeof wm === 'object' ? (wm.uri ?? wm.file) : wm;
    notes.push(`weave maps skipped: ${fileName} names weave maps (${typeof named === 'string' ? named : JSON.stringify(named)}), and a file opened with the file picker cannot fetch the files next to it, so it is drawn uniform. To see the weave: ${how}`);
  }
  if (json?.metadata?.type === 'Material' && Array.isArray(json.images) && json.images.length) {
    notes.push(`textures skipped: ${fileName} names ${json.images.length} image${json.images.length > 1 ? 's' : ''} (three.js JSON "images"), and a file opened with the file picker cannot fetch the files next to it, so it is drawn without its textures. To see them: ${how}`);
  }
  return notes;
}

/**
 * A preset opened with the file picker (a File, or anything with name and text()): parsed and
 * loaded with `load` (web/clothfit.js loadClothfitPreset) without its weave maps and textures
 * (localFileNotes says why). Returns {material, notes}; throws an Error naming the file.
 */
export async function readLocalPreset(file, load) {
  let j, text;
  try {
    text = await file.text();
    try {
      j = JSON.parse(text);
    } catch (e) {
      throw new Error(`not JSON (${e.message})`);
    }
    const notes = localFileNotes(j, file.name);
    return { material: load(text, { weaveMaps: null, textures: null }), notes };
  } catch (e) {
    throw new Error(`${file.name}: ${errorText(e)}`);
  }
}
