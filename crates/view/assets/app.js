'use strict';
// volsplat view: the page. One WebSocket to the server; input events out, frames in.
// Protocol: docs/viewer.md. No libraries, no network but the WebSocket.

const $ = (id) => document.getElementById(id);
const view = $('view');
const ctx = view.getContext('2d', { alpha: false });

// What the page knows: the server's hello and latest state, and frame bookkeeping.
const S = {
  hello: null,
  state: null,        // { request, window, transfer_function, seq }
  tf: null,           // the transfer function shown in the editor (points, data units)
  seq: 0,             // our last event number
  ws: null,
  size: [512, 512],   // the full-quality frame's size
  fit: false,         // the image follows the view (the server's hello says so; the size menu)
  maxFit: 2048,       // longest side of a view that follows the page
  lastFinal: null,    // { header, bytes } of the latest final frame
  pendingScreenshot: false,
  frames: [],         // arrival times, for the frame rate
  valuesRange: null,  // MIP/MinIP/X-ray values of the latest final frame
  dragTf: false,
  pinInfo: false,     // keep the frame-info overlay shown (key f)
};

// A hook for tests (the browser test reads it; nothing on the page depends on it).
window.__volsplat = {
  finalFrames: 0, previewFrames: 0, lastHeader: null, lastFinalPng: null, lastScreenshot: null,
  errors: [],
  state: () => S.state, seq: () => S.seq, send: (event) => sendEvent(event),
};

// ---------------------------------------------------------------- connection

function connect() {
  const proto = location.protocol === 'https:' ? 'wss:' : 'ws:';
  // The view's size in device pixels: the server starts at it when the image follows the view
  // (no --size), so the first frame already fills the window.
  const [w, h] = fitSize();
  const ws = new WebSocket(proto + '//' + location.host + '/ws' + location.search +
    '&view=' + w + 'x' + h);
  ws.binaryType = 'arraybuffer';
  S.ws = ws;
  ws.onopen = () => { setLod('loading…'); progress('load', 0); };
  ws.onmessage = (m) => (typeof m.data === 'string' ? onText(m.data) : onBinary(m.data));
  ws.onclose = () => { setLod('disconnected'); toast('The server closed the connection.'); };
  ws.onerror = () => {};
}

function send(msg) {
  if (S.ws && S.ws.readyState === WebSocket.OPEN) S.ws.send(JSON.stringify(msg));
}

function sendEvent(event) {
  S.seq += 1;
  send({ type: 'event', seq: S.seq, event });
  return S.seq;
}

function onText(text) {
  const m = JSON.parse(text);
  switch (m.type) {
    case 'hello': onHello(m); break;
    case 'state': onState(m); break;
    case 'error':
      window.__volsplat.errors.push(m.message);
      toast(m.message);
      break;
    case 'progress': progress(m.stage, m.fraction); break;
    case 'scene': download(new Blob([JSON.stringify(m.request, null, 2) + '\n'],
      { type: 'application/json' }), 'scene.json'); break;
    case 'note': addNote(m.message); break;
    // The final frame on screen shows every event up to m.seq (they changed nothing seen);
    // after the frame itself, which may still be decoding.
    case 'shown': decoding = decoding.then(() => onShown(m)); break;
  }
}

function onShown(m) {
  const hook = window.__volsplat;
  if (S.lastFinal && S.lastFinal.header.id === m.frame) {
    S.lastFinal.header.seq = Math.max(S.lastFinal.header.seq, m.seq);
  }
  if (hook.lastHeader && hook.lastHeader.id === m.frame) {
    hook.lastHeader.seq = Math.max(hook.lastHeader.seq, m.seq);
  }
  if (S.pendingScreenshot && S.lastFinal && S.lastFinal.header.seq >= S.seq) saveScreenshot();
}

// Binary: u32 LE header length, header JSON, payload.
let decoding = Promise.resolve();
function onBinary(buf) {
  const len = new DataView(buf).getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, len)));
  const bytes = new Uint8Array(buf, 4 + len);
  if (header.type === 'file') {
    if (header.format === 'png') {
      // The screenshot: the bytes `volsplat render` writes for this scene.
      const png = bytes.slice();
      window.__volsplat.lastScreenshot = png;
      download(new Blob([png], { type: 'image/png' }), baseName() + '.png');
      return;
    }
    progress(null);
    download(new Blob([bytes], { type: 'image/gif' }), baseName() + '-turntable.gif');
    $('turntable').textContent = 'Turntable';
    turntableRunning = false;
    return;
  }
  decoding = decoding.then(() => showFrame(header, bytes)).catch((e) => toast(String(e)));
}

async function showFrame(h, bytes) {
  const type = h.format === 'png' ? 'image/png' : 'image/jpeg';
  // The code values as sent: no colour management (PNGs carry gAMA 1.0; VTK shows the
  // linear values as they are, and so does this page).
  const bitmap = await createImageBitmap(new Blob([bytes], { type }),
    { colorSpaceConversion: 'none', premultiplyAlpha: 'none' });
  const [w, h2] = h.view;
  if (view.width !== w || view.height !== h2) {
    view.width = w; view.height = h2; layout();
  }
  ctx.imageSmoothingEnabled = true;
  ctx.imageSmoothingQuality = 'low'; // bilinear, as the latency benchmark scores previews
  ctx.drawImage(bitmap, 0, 0, w, h2);
  bitmap.close();
  send({ type: 'ack', frame: h.id });
  const now = performance.now();
  S.frames.push(now);
  while (S.frames.length && now - S.frames[0] > 1000) S.frames.shift();
  const hook = window.__volsplat;
  hook.lastHeader = h;
  if (h.quality === 'final') {
    S.lastFinal = { header: h, bytes: bytes.slice() };
    hook.finalFrames += 1;
    hook.lastFinalPng = S.lastFinal.bytes;
    if (h.values_range) { S.valuesRange = h.values_range; syncWindow(); }
    progress(null);
    if (S.pendingScreenshot && h.seq >= S.seq) saveScreenshot();
  } else {
    hook.previewFrames += 1;
  }
  setLod(h);
}

// ---------------------------------------------------------------- hello and state

function onHello(h) {
  S.hello = h;
  S.fit = !!h.fit;
  if (h.max_fit_side) S.maxFit = h.max_fit_side;
  // `built-in \`head\`` reads "built-in head" (baseName() still finds the name).
  $('volume-name').textContent = h.volume.replace(/`/g, '');
  $('volume-name').title = h.volume.replace(/`/g, '') + ' — ' + h.dims.join(' × ') + ' voxels';
  document.title = h.volume.replace(/`/g, '') + ' — volsplat view';
  const sel = $('volume-select');
  sel.hidden = h.volumes.length === 0;
  sel.replaceChildren(...h.volumes.map((n) => new Option(n, n, false, n === h.volume)));
  const preset = $('preset');
  preset.replaceChildren(new Option('(edited)', ''), ...h.presets.map((p) => new Option(p, p)));
  buildCrop();
  if (!$('clip-on').checked) clipPlane(); // shows where the plane would cut, in mm
  progress(null);
}

function onState(m) {
  const first = !S.state;
  S.state = m;
  const r = m.request;
  if (!S.fit) S.size = [r.width, r.height];
  if (!S.lastFinal && window.__volsplat.previewFrames === 0 &&
      (view.width !== r.width || view.height !== r.height)) {
    // Before the first frame: the view's own size, black, rather than a default canvas.
    view.width = r.width; view.height = r.height;
    ctx.fillStyle = '#000'; ctx.fillRect(0, 0, r.width, r.height);
    layout();
  }
  if (m.transfer_function && !S.dragTf) { S.tf = m.transfer_function; }
  const spec = r.scene.transfer_function;
  $('preset').value = spec === 'auto' ? 'auto' : (spec.preset || '');
  syncModes(); syncWindow(); syncCrop(); syncClip(); syncQuality(); drawTf();
  $('perspective').checked = !camera().parallel_projection;
  if (first) followView(); // the stage may have changed size since the page connected
}

function camera() {
  const c = S.state.request.scene.camera;
  return c.explicit ? c.explicit.camera : null;
}

function shaded() { return !!(S.tf && S.tf.shade); }

function modeName() {
  const mode = S.state ? S.state.request.mode : 'composite';
  return mode === 'composite' && shaded() ? 'shaded' : mode;
}

function syncModes() {
  const name = modeName();
  for (const b of $('modes').children) b.classList.toggle('on', b.dataset.mode === name);
  $('wl-section').hidden = !['mip', 'minip', 'xray'].includes(S.state.request.mode);
}

// ---------------------------------------------------------------- overlay, progress, toasts

// The overlay sits on the picture (which fills the view): it fades out 2 s after the final
// frame, and comes back with the next frame; `f` keeps it shown.
let overlayTimer = null;
function showOverlay(fadeLater) {
  const o = $('overlay');
  clearTimeout(overlayTimer);
  o.classList.remove('faded');
  if (fadeLater && !S.pinInfo) overlayTimer = setTimeout(() => o.classList.add('faded'), 2000);
}

function setLod(h) {
  const lod = $('lod');
  showOverlay(typeof h !== 'string' && h.quality === 'final');
  if (typeof h === 'string') { lod.textContent = h; lod.className = ''; return; }
  const fps = S.frames.length;
  if (h.quality === 'final') {
    lod.textContent = `final ${h.width}×${h.height}` + (S.fit ? '' : ' (fixed size)');
    lod.className = '';
  } else {
    const frac = h.scale >= 0.999 ? '1' : '1/' + (1 / h.scale).toFixed(h.scale > 0.3 ? 1 : 0);
    const slab = h.slab_factor > 1 ? ` · slab ×${h.slab_factor.toFixed(1)}` : '';
    const lvl = h.volume_level > 0 ? ` · level ${h.volume_level}` : '';
    lod.textContent = `preview ${frac} (${h.width}×${h.height})${slab}${lvl}`;
    lod.className = 'preview';
  }
  // Frames a second only mean something while previews stream (a drag), not at rest.
  $('timing').textContent = `render ${h.render_ms.toFixed(1)} ms · encode ` +
    `${h.encode_ms.toFixed(1)} ms` + (h.quality === 'final' ? '' : ` · ${fps} fps`);
}

let progressTimer = null;
function progress(stage, fraction) {
  const fill = $('progress-fill');
  const label = $('progress-label');
  clearTimeout(progressTimer);
  if (stage === null) {
    fill.style.width = '0';
    label.textContent = '';
    return;
  }
  fill.style.width = Math.round(100 * Math.max(0.03, fraction)) + '%';
  const words = { load: 'loading', classify: 'classifying', render: 'rendering',
    turntable: 'turntable', done: '' };
  label.textContent = (words[stage] ?? stage) + (fraction > 0 ? ' ' + Math.round(100 * fraction) + '%' : '…');
  progressTimer = setTimeout(() => progress(null), 4000);
}

let toastTimer = null;
function toast(text, info) {
  const t = $('toast');
  t.textContent = text;
  t.className = info ? 'info' : '';
  t.hidden = false;
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => { t.hidden = true; }, 5000);
}

function addNote(text) {
  $('notes-box').hidden = false;
  const li = document.createElement('li');
  li.textContent = text;
  $('notes').append(li);
}

function download(blob, name) {
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = name;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}

// ---------------------------------------------------------------- layout

function layout() {
  const stage = $('stage');
  const W = stage.clientWidth;
  const H = stage.clientHeight;
  const [w, h] = [view.width || S.size[0], view.height || S.size[1]];
  // Following the view: the image fills the stage (its pixels are the device's). A fixed
  // size: one image pixel per CSS pixel when it fits, smaller when it does not.
  const s = S.fit ? Math.min(W / w, H / h) : Math.min(1, W / w, H / h);
  const cw = Math.max(1, Math.floor(w * s));
  const ch = Math.max(1, Math.floor(h * s));
  view.style.width = cw + 'px';
  view.style.height = ch + 'px';
  view.style.left = Math.floor((W - cw) / 2) + 'px';
  view.style.top = Math.floor((H - ch) / 2) + 'px';
}

// The stage's size in device pixels, its long side at most S.maxFit (the aspect kept).
function fitSize() {
  const stage = $('stage');
  const dpr = window.devicePixelRatio || 1;
  const W = Math.max(16, stage.clientWidth * dpr);
  const H = Math.max(16, stage.clientHeight * dpr);
  const k = Math.min(1, S.maxFit / Math.max(W, H));
  return [Math.max(16, Math.round(W * k)), Math.max(16, Math.round(H * k))];
}

// When the image follows the view, a new stage size (the window, the browser's zoom) is sent
// once it has settled: a resize drag would otherwise ask for a frame per step.
let resizeTimer = null;
function followView() {
  clearTimeout(resizeTimer);
  if (!S.fit || !S.state) return;
  resizeTimer = setTimeout(() => {
    const [w, h] = fitSize();
    const r = S.state.request;
    if (w !== r.width || h !== r.height) sendEvent({ type: 'resize', width: w, height: h });
  }, 200);
}
function onStageResize() { layout(); followView(); }

// ---------------------------------------------------------------- camera input

// Image pixels per CSS pixel: events are in the full-quality frame's pixels.
function toImage() { return view.width / Math.max(1, view.clientWidth); }

const pointers = new Map();
let gesture = null;      // 'orbit' | 'pan' | 'zoom' | 'roll' | 'pinch'
let pending = { orbit: [0, 0], pan: [0, 0], zoom: 1, roll: 0 };
let flushQueued = false;

function queue(kind, a, b) {
  if (kind === 'orbit' || kind === 'pan') { pending[kind][0] += a; pending[kind][1] += b; }
  if (kind === 'zoom') pending.zoom *= a;
  if (kind === 'roll') pending.roll += a;
  if (!flushQueued) { flushQueued = true; requestAnimationFrame(flush); }
}

// Input is sent at most once per display frame: whatever moved since the last one.
function flush() {
  flushQueued = false;
  const p = pending;
  pending = { orbit: [0, 0], pan: [0, 0], zoom: 1, roll: 0 };
  if (p.orbit[0] || p.orbit[1]) sendEvent({ type: 'orbit', dx: p.orbit[0], dy: p.orbit[1] });
  if (p.pan[0] || p.pan[1]) sendEvent({ type: 'pan', dx: p.pan[0], dy: p.pan[1] });
  if (p.zoom !== 1) sendEvent({ type: 'zoom', factor: Math.min(1000, Math.max(0.001, p.zoom)) });
  if (p.roll) sendEvent({ type: 'roll', degrees: p.roll });
}

function gestureFor(e) {
  if (e.button === 1 || e.shiftKey) return 'pan';
  if (e.button === 2 || e.ctrlKey || e.metaKey) return 'zoom';
  if (e.altKey) return 'roll';
  return 'orbit';
}

view.addEventListener('contextmenu', (e) => e.preventDefault());
view.addEventListener('pointerdown', (e) => {
  view.focus();
  view.setPointerCapture(e.pointerId);
  pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
  if (pointers.size === 1) {
    gesture = gestureFor(e);
    sendEvent({ type: 'interaction', active: true });
  } else if (pointers.size === 2) {
    gesture = 'pinch';
  }
  view.classList.add('dragging');
});

view.addEventListener('pointermove', (e) => {
  const p = pointers.get(e.pointerId);
  if (!p) return;
  const k = toImage();
  const dx = (e.clientX - p.x) * k;
  const dy = (e.clientY - p.y) * k;
  if (gesture === 'pinch') {
    const others = [...pointers.entries()].filter(([id]) => id !== e.pointerId);
    if (others.length) {
      const o = others[0][1];
      const before = Math.hypot(p.x - o.x, p.y - o.y);
      const after = Math.hypot(e.clientX - o.x, e.clientY - o.y);
      if (before > 1 && after > 1) queue('zoom', after / before);
      const a0 = Math.atan2(p.y - o.y, p.x - o.x);
      const a1 = Math.atan2(e.clientY - o.y, e.clientX - o.x);
      queue('roll', -(a1 - a0) * 180 / Math.PI);
      queue('pan', dx / 2, dy / 2);
    }
  } else if (gesture === 'zoom') {
    queue('zoom', Math.pow(1.01, -dy / k));
  } else if (gesture === 'roll') {
    const r = view.getBoundingClientRect();
    const cx = r.left + r.width / 2;
    const cy = r.top + r.height / 2;
    const a0 = Math.atan2(p.y - cy, p.x - cx);
    const a1 = Math.atan2(e.clientY - cy, e.clientX - cx);
    let d = (a1 - a0) * 180 / Math.PI;
    if (d > 180) d -= 360;
    if (d < -180) d += 360;
    queue('roll', -d);
  } else {
    queue(gesture, dx, dy);
  }
  p.x = e.clientX;
  p.y = e.clientY;
});

function pointerEnd(e) {
  if (!pointers.delete(e.pointerId)) return;
  if (pointers.size === 0) {
    flush();
    gesture = null;
    view.classList.remove('dragging');
    sendEvent({ type: 'interaction', active: false });
  } else if (pointers.size === 1) {
    gesture = 'orbit';
  }
}
view.addEventListener('pointerup', pointerEnd);
view.addEventListener('pointercancel', pointerEnd);

view.addEventListener('wheel', (e) => {
  e.preventDefault();
  // VTK's trackball: 1.1² per wheel notch (100 pixels of delta).
  const px = e.deltaMode === 1 ? e.deltaY * 33 : e.deltaY;
  queue('zoom', Math.pow(1.1, -2 * px / 100));
}, { passive: false });

// ---------------------------------------------------------------- buttons and keys

for (const b of $('modes').children) {
  b.addEventListener('click', () => setMode(b.dataset.mode));
}

function setMode(name) {
  if (!S.state) return;
  const mode = name === 'shaded' ? 'composite' : name;
  if (S.state.request.mode !== mode) sendEvent({ type: 'set_mode', mode });
  if (mode === 'composite' && S.tf && shaded() !== (name === 'shaded')) {
    S.tf = { ...S.tf, shade: name === 'shaded' };
    sendTf();
  }
}

for (const b of document.querySelectorAll('[data-view]')) {
  b.addEventListener('click', () => sendEvent({ type: 'set_view', view: b.dataset.view }));
}
$('reset').addEventListener('click', () => sendEvent({ type: 'reset' }));
$('perspective').addEventListener('change', (e) => {
  const c = camera();
  if (!c) return;
  const cam = { ...c, parallel_projection: !e.target.checked };
  if (!e.target.checked) {
    // Keep the framing of the focal plane, as VTK's ParallelProjectionOn users do.
    const d = Math.hypot(...c.position.map((v, i) => v - c.focal_point[i]));
    cam.parallel_scale = d * Math.tan(c.view_angle * Math.PI / 360);
  }
  sendEvent({ type: 'set_camera', camera: cam });
});

$('screenshot').addEventListener('click', screenshot);
// The screenshot is the final frame of what is on screen: asked for once it has arrived.
function screenshot() {
  if (S.lastFinal && S.lastFinal.header.seq >= S.seq && !pointers.size) saveScreenshot();
  else { S.pendingScreenshot = true; toast('Waiting for the full-quality frame…', true); }
}
function saveScreenshot() {
  S.pendingScreenshot = false;
  send({ type: 'screenshot' });
}

// The volume's name without its extension (`built-in \`head\`` → head).
function baseName() {
  if (!S.hello) return 'volsplat';
  const v = S.hello.volume;
  const builtin = v.match(/`([^`]+)`/);
  return builtin ? builtin[1] : v.replace(/\.(nii\.gz|nrrd|nhdr|[^.]*)$/, '');
}

$('save-scene').addEventListener('click', () => send({ type: 'save_scene' }));

let turntableRunning = false;
$('turntable').addEventListener('click', () => {
  if (turntableRunning) {
    send({ type: 'cancel' });
    turntableRunning = false;
    $('turntable').textContent = 'Turntable';
    progress(null);
    return;
  }
  turntableRunning = true;
  $('turntable').textContent = 'Cancel turntable';
  send({ type: 'turntable', frames: 36, degrees: 360, fps: 12, max_size: 384 });
});

$('help-button').addEventListener('click', () => { $('help').hidden = !$('help').hidden; });
$('volume-select').addEventListener('change', (e) => send({ type: 'open', name: e.target.value }));

document.addEventListener('keydown', (e) => {
  if (e.target.tagName === 'INPUT' || e.target.tagName === 'SELECT' || e.ctrlKey || e.metaKey) return;
  const views = { a: 'anterior', p: 'posterior', l: 'left', r: 'right', s: 'superior', i: 'inferior' };
  const modes = ['composite', 'shaded', 'mip', 'minip', 'xray'];
  const k = e.key;
  const step = 5 * view.width / 200; // 5° of VTK's trackball azimuth per arrow press
  const arrows = { ArrowLeft: [-step, 0], ArrowRight: [step, 0], ArrowUp: [0, -step], ArrowDown: [0, step] };
  if (views[k.toLowerCase()] && !e.altKey) sendEvent({ type: 'set_view', view: views[k.toLowerCase()] });
  else if (k === '0' || k === 'Home') sendEvent({ type: 'reset' });
  else if (k >= '1' && k <= '5') setMode(modes[+k - 1]);
  else if (arrows[k]) { queue(e.shiftKey ? 'pan' : 'orbit', -arrows[k][0], -arrows[k][1]); }
  else if (k === '+' || k === '=') queue('zoom', 1.21);
  else if (k === '-' || k === '_') queue('zoom', 1 / 1.21);
  else if (k === 'q') queue('roll', 5);
  else if (k === 'e') queue('roll', -5);
  else if (k === 'c') screenshot();
  else if (k === 'j') send({ type: 'save_scene' });
  else if (k === 't') $('turntable').click();
  else if (k === '?' || k === 'h') $('help').hidden = !$('help').hidden;
  else if (k === 'f') { S.pinInfo = !S.pinInfo; showOverlay(!S.pinInfo); }
  else if (k === 'Escape') $('help').hidden = true;
  else return;
  e.preventDefault();
});

// Sliders: a held slider is a drag (previews), its release refines.
for (const el of document.querySelectorAll('#panel input[type=range]')) {
  el.addEventListener('pointerdown', () => sendEvent({ type: 'interaction', active: true }));
  el.addEventListener('pointerup', () => sendEvent({ type: 'interaction', active: false }));
}

// ---------------------------------------------------------------- window / level

function valueSpan() {
  if (S.state && S.state.request.mode === 'xray' && S.valuesRange) return [0, S.valuesRange[1]];
  return S.hello ? S.hello.value_range : [0, 1];
}

function syncWindow() {
  if (!S.state) return;
  const [lo, hi] = valueSpan();
  const span = Math.max(hi - lo, 1e-6);
  const w = S.state.window || (S.state.request.mode === 'xray' ? [0, hi] : [lo, hi]);
  $('level').value = Math.round(1000 * (((w[0] + w[1]) / 2) - lo) / span);
  $('width').value = Math.max(1, Math.round(1000 * (w[1] - w[0]) / span));
  $('level-out').textContent = fmt((w[0] + w[1]) / 2);
  $('width-out').textContent = fmt(w[1] - w[0]);
  // Say what the sliders do now: MIP and MinIP show the transfer function until a window is
  // set; X-ray never uses the transfer function.
  const mode = S.state.request.mode;
  const xray = mode === 'xray';
  $('wl-auto').textContent = xray ? 'Auto' : 'Transfer function';
  $('wl-auto').disabled = !S.state.window;
  $('wl-hint').textContent = S.state.window ? 'grey window on'
    : xray ? '0 to the brightest pixel' : 'off: colours of the transfer function';
  const unused = xray ? 'X-ray integrates the data itself: the transfer function is not used.'
    : (S.state.window && mode !== 'composite')
      ? 'A grey window is set: the transfer function is not used (Window / level → Transfer function).'
      : '';
  $('tf-section').classList.toggle('unused', !!unused);
  $('tf-unused').hidden = !unused;
  $('tf-unused').textContent = unused;
}

function sendWindow() {
  const [lo, hi] = valueSpan();
  const span = Math.max(hi - lo, 1e-6);
  const level = lo + span * $('level').value / 1000;
  const width = Math.max(span * $('width').value / 1000, span * 1e-4);
  $('level-out').textContent = fmt(level);
  $('width-out').textContent = fmt(width);
  sendEvent({ type: 'set_window', window: [level - width / 2, level + width / 2] });
}
$('level').addEventListener('input', sendWindow);
$('width').addEventListener('input', sendWindow);
$('wl-auto').addEventListener('click', () => sendEvent({ type: 'set_window', window: null }));

function fmt(v) {
  const a = Math.abs(v);
  return a >= 1000 ? v.toFixed(0) : a >= 10 ? v.toFixed(1) : v.toPrecision(3);
}

// ---------------------------------------------------------------- crop box and clip plane

const cropInputs = [];
const cropOutputs = [];
function buildCrop() {
  const box = $('crop');
  box.replaceChildren();
  cropInputs.length = 0;
  cropOutputs.length = 0;
  for (let k = 0; k < 3; k++) {
    const n = S.hello.dims[k] - 1;
    const label = document.createElement('span');
    label.textContent = 'xyz'[k];
    box.append(label);
    const out = document.createElement('output');
    for (let j = 0; j < 2; j++) {
      const r = document.createElement('input');
      r.type = 'range'; r.min = 0; r.max = n; r.step = 1; r.value = j ? n : 0;
      r.title = (j ? 'last ' : 'first ') + 'xyz'[k] + ' voxel kept';
      r.addEventListener('input', () => {
        if (+cropInputs[2 * k].value > +cropInputs[2 * k + 1].value) {
          cropInputs[2 * k + (j ? 0 : 1)].value = r.value;
        }
        $('crop-on').checked = true;
        showCrop();
        sendCrop();
      });
      r.addEventListener('pointerdown', () => sendEvent({ type: 'interaction', active: true }));
      r.addEventListener('pointerup', () => sendEvent({ type: 'interaction', active: false }));
      cropInputs.push(r);
      box.append(r);
    }
    cropOutputs.push(out);
    box.append(out);
  }
  showCrop();
}

// The voxels kept per axis, as numbers beside the sliders.
function showCrop() {
  for (let k = 0; k < cropOutputs.length; k++) {
    cropOutputs[k].textContent = cropInputs[2 * k].value + '–' + cropInputs[2 * k + 1].value;
  }
}

function sendCrop() {
  if (!$('crop-on').checked) { sendEvent({ type: 'set_crop', crop: null }); return; }
  const v = cropInputs.map((r) => +r.value);
  sendEvent({ type: 'set_crop', crop: { min: [v[0], v[2], v[4]], max: [v[1], v[3], v[5]], units: 'voxels' } });
}
$('crop-on').addEventListener('change', sendCrop);

function syncCrop() {
  const crop = (S.state.request.scene.clipping || {}).crop;
  $('crop-on').checked = !!crop;
  if (crop && crop.units === 'voxels' && cropInputs.length === 6) {
    for (let k = 0; k < 3; k++) {
      cropInputs[2 * k].value = crop.min[k];
      cropInputs[2 * k + 1].value = crop.max[k];
    }
  }
  showCrop();
}

function clipPlane() {
  const k = +$('clip-axis').value;
  const [lo, hi] = [S.hello.bounds[0][k], S.hello.bounds[1][k]];
  const at = lo + (hi - lo) * $('clip-at').value / 1000;
  $('clip-out').textContent = fmt(at) + ' mm';
  const flip = $('clip-flip').checked;
  const normal = [0, 0, 0];
  normal[k] = flip ? -1 : 1;
  return { normal, offset: flip ? at : -at }; // keeps normal·x + offset ≥ 0
}

function sendClip() {
  if (!S.hello) return;
  const plane = clipPlane(); // also shows where it cuts
  const planes = $('clip-on').checked ? [plane] : [];
  sendEvent({ type: 'set_clip', planes });
}
for (const id of ['clip-on', 'clip-axis', 'clip-flip']) $(id).addEventListener('change', sendClip);
$('clip-at').addEventListener('input', () => { $('clip-on').checked = true; sendClip(); });

function syncClip() {
  const planes = (S.state.request.scene.clipping || {}).planes || [];
  $('clip-on').checked = planes.length > 0;
  const p = planes[0];
  if (!p || !S.hello) return;
  const k = p.normal.findIndex((v) => v !== 0);
  if (k < 0 || p.normal.filter((v) => v !== 0).length !== 1) return;
  const flip = p.normal[k] < 0;
  const at = flip ? p.offset / -p.normal[k] : -p.offset / p.normal[k];
  const [lo, hi] = [S.hello.bounds[0][k], S.hello.bounds[1][k]];
  $('clip-axis').value = k;
  $('clip-flip').checked = flip;
  $('clip-at').value = Math.round(1000 * (at - lo) / Math.max(hi - lo, 1e-9));
  $('clip-out').textContent = fmt(at) + ' mm';
}

// ---------------------------------------------------------------- quality and size

const QUALITY = ['antialias', 'preintegrate', 'shade_at', 'slab', 'opacity_cutoff'];
function syncQuality() {
  const q = S.state.request.quality;
  for (const f of QUALITY) {
    const el = $('q-' + f);
    const v = q[f] === null || q[f] === undefined ? '' : String(q[f]);
    if (f === 'opacity_cutoff') el.value = q[f] >= 1 ? '1' : q[f] > 0.9999 ? '0.999999' : '0.9922180';
    else el.value = v;
  }
  const [w, h] = [S.state.request.width, S.state.request.height];
  const size = $('size');
  let fixed = size.querySelector('option[value=fixed]');
  if (S.fit) {
    size.value = 'fit';
  } else if (w === h && [256, 384, 512, 768, 1024].includes(w)) {
    size.value = String(w);
  } else {
    // A size of its own (--size 80x64, a scene file's): shown as it is, not as "fit".
    if (!fixed) { fixed = new Option('', 'fixed'); size.append(fixed); }
    fixed.textContent = `${w} × ${h}`;
    size.value = 'fixed';
  }
}
for (const f of QUALITY) {
  $('q-' + f).addEventListener('change', (e) => {
    const q = { ...S.state.request.quality };
    const v = e.target.value;
    q[f] = f === 'slab' ? (v === '' ? null : +v) : f === 'opacity_cutoff' ? +v : v;
    sendEvent({ type: 'set_quality', quality: q });
  });
}
$('size').addEventListener('change', (e) => {
  if (e.target.value === 'fixed') return;
  S.fit = e.target.value === 'fit';
  const [w, h] = S.fit ? fitSize() : [+e.target.value, +e.target.value];
  layout();
  sendEvent({ type: 'resize', width: w, height: h });
});

// ---------------------------------------------------------------- transfer function editor

const tfCanvas = $('tf');
const tfc = tfCanvas.getContext('2d');
const TF = { W: 296, H: 170, plotH: 138, barY: 146, barH: 20, r: 5, pad: 7 };
let tfDrag = null;   // { kind: 'opacity' | 'color', index, moved }

(function hiDpi() {
  const d = window.devicePixelRatio || 1;
  tfCanvas.width = TF.W * d;
  tfCanvas.height = TF.H * d;
  tfc.scale(d, d);
})();

function tfRange() {
  const [lo, hi] = S.hello ? S.hello.value_range : [0, 1];
  return hi > lo ? [lo, hi] : [lo, lo + 1];
}
// The value axis keeps TF.pad pixels free at both ends, so the points at the ends of the
// range are whole circles one can grab; opacity 0 sits clear of the colour stops below.
const TF_IW = TF.W - 2 * TF.pad;
const xOf = (v) => { const [lo, hi] = tfRange(); return TF.pad + ((v - lo) / (hi - lo)) * TF_IW; };
const vOf = (x) => { const [lo, hi] = tfRange(); return lo + ((x - TF.pad) / TF_IW) * (hi - lo); };
const yOf = (a) => 6 + (1 - a) * (TF.plotH - 18);
const aOf = (y) => Math.min(1, Math.max(0, 1 - (y - 6) / (TF.plotH - 18)));

function colorAt(v) {
  const c = S.tf.color;
  if (v <= c[0][0]) return c[0].slice(1);
  for (let i = 1; i < c.length; i++) {
    if (v <= c[i][0]) {
      const t = c[i][0] > c[i - 1][0] ? (v - c[i - 1][0]) / (c[i][0] - c[i - 1][0]) : 1;
      return [1, 2, 3].map((k) => c[i - 1][k] + t * (c[i][k] - c[i - 1][k]));
    }
  }
  return c[c.length - 1].slice(1);
}
const css = (rgb, a = 1) => `rgba(${rgb.map((x) => Math.round(255 * Math.min(1, Math.max(0, x)))).join(',')},${a})`;

function drawTf() {
  tfc.clearRect(0, 0, TF.W, TF.H);
  if (!S.hello) return;
  // Histogram, log counts.
  const h = S.hello.histogram;
  const max = Math.log1p(Math.max(...h));
  tfc.fillStyle = '#39414b';
  const bw = TF_IW / h.length;
  for (let i = 0; i < h.length; i++) {
    const t = max > 0 ? Math.log1p(h[i]) / max : 0;
    tfc.fillRect(TF.pad + i * bw, TF.plotH - t * TF.plotH, Math.ceil(bw), t * TF.plotH);
  }
  if (!S.tf) return;
  const op = S.tf.scalar_opacity;
  const [lo, hi] = tfRange();
  // Area under the opacity curve in the transfer function's colours.
  const grad = tfc.createLinearGradient(TF.pad, 0, TF.pad + TF_IW, 0);
  for (let i = 0; i <= 32; i++) {
    const v = lo + (i / 32) * (hi - lo);
    grad.addColorStop(i / 32, css(colorAt(v), 0.55));
  }
  const pts = [[Math.min(0, xOf(op[0][0])), yOf(op[0][1])],
    ...op.map((p) => [xOf(p[0]), yOf(p[1])]),
    [Math.max(TF.W, xOf(op[op.length - 1][0])), yOf(op[op.length - 1][1])]];
  tfc.beginPath();
  tfc.moveTo(pts[0][0], yOf(0));
  for (const [x, y] of pts) tfc.lineTo(x, y);
  tfc.lineTo(pts[pts.length - 1][0], yOf(0));
  tfc.closePath();
  tfc.fillStyle = grad;
  tfc.fill();
  tfc.beginPath();
  pts.forEach(([x, y], i) => (i ? tfc.lineTo(x, y) : tfc.moveTo(x, y)));
  tfc.strokeStyle = '#e8edf2';
  tfc.lineWidth = 1.5;
  tfc.stroke();
  for (const [v, a] of op) {
    tfc.beginPath();
    tfc.arc(xOf(v), yOf(a), TF.r, 0, 2 * Math.PI);
    tfc.fillStyle = '#0d0f11';
    tfc.fill();
    tfc.strokeStyle = '#e8edf2';
    tfc.stroke();
  }
  // Colour bar and its stops.
  const bar = tfc.createLinearGradient(TF.pad, 0, TF.pad + TF_IW, 0);
  for (let i = 0; i <= 64; i++) bar.addColorStop(i / 64, css(colorAt(lo + (i / 64) * (hi - lo))));
  tfc.fillStyle = bar;
  tfc.fillRect(0, TF.barY, TF.W, TF.barH);
  for (const c of S.tf.color) {
    const x = xOf(c[0]);
    tfc.beginPath();
    tfc.moveTo(x, TF.barY - 1);
    tfc.lineTo(x - 5, TF.barY - 8);
    tfc.lineTo(x + 5, TF.barY - 8);
    tfc.closePath();
    tfc.fillStyle = css(c.slice(1));
    tfc.fill();
    tfc.strokeStyle = '#e8edf2';
    tfc.lineWidth = 1;
    tfc.stroke();
  }
  tfc.fillStyle = '#aab3bd';
  tfc.font = '10px system-ui, sans-serif';
  tfc.fillText(fmt(lo), 3, 12);
  const hiText = fmt(hi);
  tfc.fillText(hiText, TF.W - tfc.measureText(hiText).width - 3, 12);
}

function tfHit(x, y) {
  if (!S.tf) return null;
  if (y >= TF.barY - 10) {
    let best = null;
    S.tf.color.forEach((c, i) => {
      const d = Math.abs(xOf(c[0]) - x);
      if (d <= 7 && (!best || d < best.d)) best = { kind: 'color', index: i, d };
    });
    return best;
  }
  let best = null;
  S.tf.scalar_opacity.forEach((p, i) => {
    const d = Math.hypot(xOf(p[0]) - x, yOf(p[1]) - y);
    if (d <= TF.r + 4 && (!best || d < best.d)) best = { kind: 'opacity', index: i, d };
  });
  return best;
}

function tfPos(e) {
  const r = tfCanvas.getBoundingClientRect();
  return [(e.clientX - r.left) * TF.W / r.width, (e.clientY - r.top) * TF.H / r.height];
}

let tfSendQueued = false;
function sendTf() {
  $('preset').value = '';
  drawTf();
  if (tfSendQueued) return;
  tfSendQueued = true;
  requestAnimationFrame(() => {
    tfSendQueued = false;
    sendEvent({ type: 'set_transfer_function', transfer_function: { function: S.tf } });
  });
}

function clampBetween(list, i, v) {
  const lo = i > 0 ? list[i - 1][0] : -1e38;
  const hi = i < list.length - 1 ? list[i + 1][0] : 1e38;
  return Math.min(hi, Math.max(lo, v));
}

tfCanvas.addEventListener('pointerdown', (e) => {
  if (!S.tf || e.button !== 0) return;
  const [x, y] = tfPos(e);
  const hit = tfHit(x, y);
  if (!hit) return;
  tfCanvas.setPointerCapture(e.pointerId);
  S.tf = structuredClone(S.tf);
  tfDrag = { ...hit, moved: false };
  S.dragTf = true;
  sendEvent({ type: 'interaction', active: true });
});

tfCanvas.addEventListener('pointermove', (e) => {
  if (!tfDrag) {
    const [x, y] = tfPos(e);
    tfCanvas.style.cursor = tfHit(x, y) ? 'move' : 'crosshair';
    return;
  }
  const [x, y] = tfPos(e);
  const list = tfDrag.kind === 'opacity' ? S.tf.scalar_opacity : S.tf.color;
  const p = list[tfDrag.index];
  p[0] = clampBetween(list, tfDrag.index, vOf(Math.min(TF.pad + TF_IW, Math.max(TF.pad, x))));
  if (tfDrag.kind === 'opacity') p[1] = aOf(y);
  tfDrag.moved = true;
  sendTf();
});

function tfEnd() {
  if (!tfDrag) return;
  const d = tfDrag;
  tfDrag = null;
  S.dragTf = false;
  sendEvent({ type: 'interaction', active: false });
  if (d.kind === 'color' && !d.moved) pickColor(d.index);
}
tfCanvas.addEventListener('pointerup', tfEnd);
tfCanvas.addEventListener('pointercancel', tfEnd);

tfCanvas.addEventListener('dblclick', (e) => {
  if (!S.tf) return;
  const [x, y] = tfPos(e);
  const hit = tfHit(x, y);
  S.tf = structuredClone(S.tf);
  if (hit) { removePoint(hit); return; }
  const v = vOf(x);
  if (y >= TF.barY - 10) {
    const c = S.tf.color;
    const i = c.findIndex((p) => p[0] > v);
    c.splice(i < 0 ? c.length : i, 0, [v, ...colorAt(v)]);
  } else {
    const o = S.tf.scalar_opacity;
    const i = o.findIndex((p) => p[0] > v);
    o.splice(i < 0 ? o.length : i, 0, [v, aOf(y)]);
  }
  sendTf();
});

tfCanvas.addEventListener('contextmenu', (e) => {
  e.preventDefault();
  const [x, y] = tfPos(e);
  const hit = tfHit(x, y);
  if (!hit) return;
  S.tf = structuredClone(S.tf);
  removePoint(hit);
});

function removePoint(hit) {
  const list = hit.kind === 'opacity' ? S.tf.scalar_opacity : S.tf.color;
  if (list.length <= 1) { toast('A transfer function keeps at least one point of each kind.', true); return; }
  list.splice(hit.index, 1);
  sendTf();
}

function pickColor(index) {
  const picker = $('color-picker');
  const c = S.tf.color[index];
  picker.value = '#' + c.slice(1).map((x) => Math.round(255 * x).toString(16).padStart(2, '0')).join('');
  picker.oninput = () => {
    const hex = picker.value;
    S.tf = structuredClone(S.tf);
    const p = S.tf.color[index];
    for (let k = 0; k < 3; k++) p[k + 1] = parseInt(hex.substr(1 + 2 * k, 2), 16) / 255;
    sendTf();
  };
  picker.click();
}

$('preset').addEventListener('change', (e) => {
  const v = e.target.value;
  if (!v) return;
  sendEvent({ type: 'set_transfer_function', transfer_function: v === 'auto' ? 'auto' : { preset: v } });
});

// ---------------------------------------------------------------- start

window.addEventListener('load', () => { layout(); drawTf(); });
new ResizeObserver(onStageResize).observe($('stage'));
connect();
