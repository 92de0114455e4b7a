// foveated-mi live view: the page. No build step, no dependencies.
// Frames arrive as one binary WebSocket message each: a 4-byte big-endian length n, n bytes
// of JSON (the frame's numbers), then a JPEG. Every frame drawn is acknowledged, which is how
// the server knows this page has room for the next one (it drops frames rather than queue).
// What the page sends is a fixed set of JSON messages (foveated_mi/live/protocol.py).
"use strict";
(() => {
  const $ = (id) => document.getElementById(id);
  const token = new URLSearchParams(location.search).get("token") || "";
  // Everything a test or a benchmark reads lives here.
  const live = window.live = {
    received: 0, meta: null, state: null, errors: [], lastError: "", refused: "",
    recording: null, rebuild: null, latencies: [], arrivals: [], frames: [], closed: false,
    gazeSent: 0,
  };
  const view = $("view"), ctx = view.getContext("2d"), svg = $("overlay");
  const SVGNS = "http://www.w3.org/2000/svg";
  const RING_DEG = [5, 10, 20, 30, 45, 60];
  const SPEED = 0.5;      // camera distances per second
  const TURN = 60;        // degrees per second
  let ws = null, seq = 0, dragging = null, chain = Promise.resolve();
  const sentAt = new Map();
  let pending = [];       // gaze seqs sent and not yet seen in a frame
  const held = new Set();

  function send(obj) {
    if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(obj));
  }

  function setConn(text, ok) {
    const c = $("conn");
    c.textContent = text;
    c.className = ok ? "good" : "bad";
  }

  function connect() {
    const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws" +
      (token ? "?token=" + encodeURIComponent(token) : "");
    ws = new WebSocket(url);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => setConn("connected", true);
    ws.onclose = () => {
      live.closed = true;
      setConn(live.refused ? "refused" : "disconnected (reload to reconnect)", false);
    };
    ws.onmessage = (ev) => {
      if (typeof ev.data === "string") {
        onText(JSON.parse(ev.data));
      } else {
        const buf = ev.data;
        chain = chain.then(() => onFrame(buf)).catch((e) => console.error(e));
      }
    };
  }

  // ---- messages -----------------------------------------------------------------------
  function showError(text) {
    live.lastError = text;
    live.errors.push(text);
    $("error").textContent = text;
  }

  function onText(m) {
    if (m.type === "state") {
      live.state = m;
      fillControls(m);
    } else if (m.type === "error") {
      showError(m.message);
    } else if (m.type === "refused") {
      live.refused = m.message;
      showError(m.message);
    } else if (m.type === "recording") {
      live.recording = m;
      const div = $("recording");
      div.textContent = "";
      for (const [name, text, type] of [[m.toml_name, m.toml, "application/toml"],
                                        [m.csv_name, m.csv, "text/csv"]]) {
        const a = document.createElement("a");
        a.href = URL.createObjectURL(new Blob([text], {type}));
        a.download = name;
        a.textContent = name;
        div.appendChild(a);
      }
      const p = document.createElement("div");
      p.textContent = `${m.frames} frames, saved as ${m.toml_path}; ` +
        `replay: foveated-mi sequence ${m.toml_name}`;
      div.appendChild(p);
    }
  }

  function fillSelect(sel, values, current) {
    if (sel.options.length !== values.length) {
      sel.textContent = "";
      for (const v of values) {
        const o = document.createElement("option");
        o.value = o.textContent = v;
        sel.appendChild(o);
      }
    }
    if (document.activeElement !== sel) sel.value = current;
  }

  function fillControls(s) {
    $("scene").textContent = `${s.scene}, ${s.width}x${s.height}, ${s.variant}`;
    fillSelect($("preset"), s.presets, s.preset);
    fillSelect($("denoiser"), s.denoisers, s.denoiser);
    for (const [id, v] of [["ray_budget", s.ray_budget], ["spp", s.spp],
                           ["latency", s.latency_ms]]) {
      if (document.activeElement !== $(id)) $(id).value = String(v);
    }
    for (const box of document.querySelectorAll("input[data-overlay]")) {
      box.checked = s.overlays.includes(box.dataset.overlay);
    }
    $("split").value = s.split;
    $("lock").checked = s.locked;
    if (document.activeElement !== $("source")) $("source").value = s.source;
    // The target as a rate (a --frame-ms or --fps of the command line may be none of the
    // select's: it joins them).
    const hz = s.frame_ms > 0 ? String(Number((1000 / s.frame_ms).toFixed(2))) : "0";
    const fps = $("fps");
    if (![...fps.options].some((o) => o.value === hz)) {
      const o = document.createElement("option");
      o.value = hz;
      o.textContent = `${hz} Hz`;
      fps.appendChild(o);
    }
    if (document.activeElement !== fps) fps.value = hz;
    $("record").textContent = s.recording ? "Stop recording" : "Record";
    $("record").classList.toggle("on", s.recording);
  }

  // ---- frames -------------------------------------------------------------------------
  async function onFrame(buf) {
    const n = new DataView(buf).getUint32(0, false);
    const meta = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
    const bmp = await createImageBitmap(new Blob([new Uint8Array(buf, 4 + n)],
                                                 {type: "image/jpeg"}));
    if (view.width !== bmp.width || view.height !== bmp.height) {
      view.width = bmp.width;
      view.height = bmp.height;
      svg.setAttribute("viewBox", `0 0 ${bmp.width} ${bmp.height}`);
    }
    ctx.drawImage(bmp, 0, 0);
    bmp.close();
    send({type: "ack", frame: meta.frame});
    const t = performance.now();
    while (pending.length && pending[0] <= meta.gaze_seq) {
      const s = pending.shift();
      const t0 = sentAt.get(s);
      sentAt.delete(s);
      if (t0 !== undefined) live.latencies.push(t - t0);
    }
    if (live.latencies.length > 5000) live.latencies.splice(0, 1000);
    live.received += 1;
    live.meta = meta;
    live.arrivals.push(t);
    if (live.arrivals.length > 5000) live.arrivals.splice(0, 1000);
    live.frames.push({frame: meta.frame, gaze: meta.gaze, gaze_seq: meta.gaze_seq,
                      camera: meta.camera, cut: meta.cut, history_frame: meta.history_frame,
                      preset: meta.preset, overlays: meta.overlays, frame_ms: meta.frame_ms, t});
    if (live.frames.length > 1000) live.frames.splice(0, 200);
    if (meta.rebuild) {
      live.rebuild = meta.rebuild;
      const what = Object.entries(meta.rebuild.changed).map(([k, v]) => `${k} = ${v}`).join(", ");
      $("rebuild").textContent = `${what}: rebuilt in ${meta.rebuild.ms.toFixed(0)} ms ` +
        `(its first frame ${meta.rebuild.first_frame_ms.toFixed(0)} ms)`;
    }
    hud(meta, t);
    drawOverlay(meta);
  }

  function fmt(v, digits) { return v === null || v === undefined ? "-" : v.toFixed(digits); }

  function hud(m, t) {
    let k = live.arrivals.length - 1;
    while (k >= 0 && live.arrivals[k] > t - 1000) k -= 1;
    const fps = live.arrivals.length - 1 - k;
    const lat = live.latencies.slice(-30).sort((a, b) => a - b);
    const latMed = lat.length ? lat[lat.length >> 1] : null;
    $("hud").textContent =
      `${fps} fps shown · frame ${fmt(m.frame_ms, 1)} ms · rays ${fmt(100 * m.ray_fraction, 1)} %` +
      ` · history ${m.history_frame}${m.cut ? " (cut)" : ""}` +
      ` · hit ${fmt(100 * (m.history_hit_rate || 0), 0)} % · dropped ${m.dropped}` +
      ` · gaze latency ${fmt(latMed, 0)} ms` + (m.recording !== null ? ` · REC ${m.recording}` : "");
    const b = m.frame_budget;
    // The budget the integrator chose this frame, its render time, and how many of the last
    // second's frames held it.
    $("budget").textContent = b ?
      `${Number(b.fps.toFixed(1))} Hz target: ${fmt(b.measured_ms, 1)} of ` +
      `${fmt(b.budget_ms, 1)} ms (rung ${b.rung}: ${b.spp} spp, ` +
      `${fmt(100 * b.ray_budget, 0)} % rays) · held ${b.held}/${b.window_frames} frames ` +
      `of the last second` : "";
    $("label-left").textContent =
      `foveated: ${m.preset_resolved}, ${b ? b.spp : m.spp} spp, ${fmt(m.frame_ms, 1)} ms` +
      (m.locked ? " · gaze locked" : "") + (m.latency_ms ? ` · +${m.latency_ms} ms latency` : "");
    const s = m.split_info;
    let right = "";
    if (s && s.mode === "uniform") {
      right = `uniform, same rays: ${s.size[0]}x${s.size[1]} upscaled, ${fmt(s.ms, 1)} ms`;
    } else if (s && s.mode === "still") {
      right = `converged still: ${s.spp}/${s.target} spp` +
        (s.spp < s.target ? " (accumulates while the camera rests)" : "");
    }
    $("label-right").textContent = right;
  }

  // ---- overlays drawn by the page: eccentricity rings, the fovea, the gaze ------------
  const norm = (v) => { const l = Math.hypot(v[0], v[1], v[2]); return [v[0] / l, v[1] / l, v[2] / l]; };
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                           a[0] * b[1] - a[1] * b[0]];

  // SVG elements are kept and reused from frame to frame (a pool per group and tag): a
  // frame changes attributes only, and nothing when the gaze and the camera are unchanged.
  const pools = new Map();
  function el(name, attrs, parent, index) {
    const key = parent.id + ":" + name;
    let pool = pools.get(key);
    if (!pool) pools.set(key, pool = []);
    let e = pool[index];
    if (!e) {
      e = document.createElementNS(SVGNS, name);
      parent.appendChild(e);
      pool[index] = e;
    }
    e.style.display = "";
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    return e;
  }
  function hideFrom(parent, name, index) {
    for (const e of (pools.get(parent.id + ":" + name) || []).slice(index)) e.style.display = "none";
  }

  // The ring of eccentricity deg around the gaze on a pinhole camera of horizontal field of
  // view fov: directions at angle deg from the gaze ray, projected to film pixels.
  function ringPolylines(m, deg) {
    const W = m.width, H = m.height;
    const tx = Math.tan(m.fov * Math.PI / 360), ty = tx * H / W;
    const g = norm([(2 * m.gaze[0] - 1) * tx, (1 - 2 * m.gaze[1]) * ty, 1]);
    let a = cross(g, [0, 1, 0]);
    if (Math.hypot(...a) < 1e-6) a = cross(g, [1, 0, 0]);
    a = norm(a);
    const b = cross(g, a);
    const e = deg * Math.PI / 180, ce = Math.cos(e), se = Math.sin(e);
    const lines = [];
    let cur = [];
    for (let k = 0; k <= 96; k++) {
      const p = 2 * Math.PI * k / 96, cp = Math.cos(p), sp = Math.sin(p);
      const d = [0, 1, 2].map((i) => g[i] * ce + (a[i] * cp + b[i] * sp) * se);
      if (d[2] <= 1e-6) {
        if (cur.length > 1) lines.push(cur);
        cur = [];
        continue;
      }
      cur.push([(d[0] / d[2] / tx + 1) / 2 * W, (1 - d[1] / d[2] / ty) / 2 * H]);
    }
    if (cur.length > 1) lines.push(cur);
    return lines;
  }

  let drawn = "";
  function drawOverlay(m) {
    const rings = $("rings"), marks = $("marks"), fg = $("fovea");
    const showRings = $("ov-rings").checked;
    rings.style.display = fg.style.display = showRings ? "" : "none";
    const key = JSON.stringify([m.gaze, m.fov, m.width, m.height, m.panels, m.fovea]);
    if (key === drawn) return;
    drawn = key;
    const W = m.width, H = m.height;
    const gx = m.gaze[0] * W, gy = m.gaze[1] * H;
    const font = Math.max(H / 22, 1.2);
    let nl = 0, nt = 0;
    for (const deg of RING_DEG) {
      if (deg > 1.2 * m.fov) continue;
      let top = null;
      for (const line of ringPolylines(m, deg)) {
        el("polyline", {class: "ecc", points: line.map((p) => p.join(",")).join(" ")}, rings, nl++);
        for (const p of line) {
          const inside = p[1] >= 1.2 * font && p[1] <= H && p[0] >= font && p[0] <= W - font;
          if (inside && (!top || p[1] < top[1])) top = p;
        }
      }
      if (top) {
        const t = el("text", {x: top[0], y: top[1] - 0.3 * font, "font-size": font,
                              "text-anchor": "middle"}, rings, nt++);
        t.textContent = `${deg}°`;
      }
    }
    hideFrom(rings, "polyline", nl);
    hideFrom(rings, "text", nt);
    const circle = m.fovea && m.fovea.px !== undefined;
    const fovea = el(circle ? "circle" : "polyline", {class: "fovea"}, fg, 0);
    hideFrom(fg, circle ? "polyline" : "circle", 0);
    for (const other of fg.querySelectorAll("#fovea-ring")) if (other !== fovea) other.removeAttribute("id");
    fovea.setAttribute("id", "fovea-ring");
    if (circle) {
      for (const [k, v] of Object.entries({cx: gx, cy: gy, r: m.fovea.px})) fovea.setAttribute(k, v);
    } else if (m.fovea) {
      fovea.setAttribute("points", ringPolylines(m, m.fovea.deg).flat().map((p) => p.join(",")).join(" "));
    } else {
      fovea.style.display = "none";
    }
    fovea.setAttribute("data-cx", gx);
    fovea.setAttribute("data-cy", gy);
    for (let k = 0; k < m.panels; k++) {
      el("circle", {class: "gaze", cx: gx + k * W, cy: gy, r: Math.max(W, H) / 120 + 0.5}, marks, k);
    }
    hideFrom(marks, "circle", m.panels);
    if (m.panels > 1) el("polyline", {class: "divider", points: `${W},0 ${W},${H}`}, marks, 0);
    else hideFrom(marks, "polyline", 0);
  }

  // ---- the gaze and the head ----------------------------------------------------------
  function panelPosition(ev) {
    const r = view.getBoundingClientRect();
    const panels = live.meta ? live.meta.panels : 1;
    let u = (ev.clientX - r.left) / r.width * panels;
    u -= Math.min(Math.floor(u), panels - 1);
    const v = (ev.clientY - r.top) / r.height;
    return [Math.min(Math.max(u, 0), 1), Math.min(Math.max(v, 0), 1), r];
  }

  const stage = $("stage");
  stage.addEventListener("mousemove", (ev) => {
    const [u, v, r] = panelPosition(ev);
    if (dragging) {
      const dx = ev.clientX - dragging.x, dy = ev.clientY - dragging.y;
      dragging = {x: ev.clientX, y: ev.clientY};
      const panels = live.meta ? live.meta.panels : 1;
      const degPerPx = (live.meta ? live.meta.fov : 60) * panels / r.width;
      const clamp = (x) => Math.max(-90, Math.min(90, x));
      send({type: "move", yaw: clamp(dx * degPerPx), pitch: clamp(-dy * degPerPx)});
      return;
    }
    if ($("lock").checked || $("source").value !== "mouse") return;
    seq += 1;
    sentAt.set(seq, ev.timeStamp || performance.now());
    pending.push(seq);
    if (pending.length > 5000) {
      for (const s of pending.splice(0, 1000)) sentAt.delete(s);
    }
    live.gazeSent = seq;
    send({type: "gaze", x: u, y: v, seq});
  });
  stage.addEventListener("mousedown", (ev) => {
    if (ev.button === 0) {
      dragging = {x: ev.clientX, y: ev.clientY};
      stage.focus();
      ev.preventDefault();
    }
  });
  window.addEventListener("mouseup", () => { dragging = null; });

  const MOTION = new Set(["w", "a", "s", "d", "q", "e", "ArrowUp", "ArrowDown", "ArrowLeft",
                          "ArrowRight"]);
  const keyName = (ev) => (ev.key.length === 1 ? ev.key.toLowerCase() : ev.key);
  const typing = (t) => t && (t.tagName === "INPUT" || t.tagName === "SELECT" ||
                              t.tagName === "TEXTAREA");
  let fast = false;
  window.addEventListener("keydown", (ev) => {
    if (typing(ev.target)) return;
    const k = keyName(ev);
    fast = ev.shiftKey;
    if (MOTION.has(k)) {
      held.add(k);
      ev.preventDefault();
    } else if (k === "h" || k === "Home") {
      send({type: "home"});
    } else if (k === "l") {
      $("lock").checked = !$("lock").checked;
      lockChanged();
    }
  });
  window.addEventListener("keyup", (ev) => { held.delete(keyName(ev)); fast = ev.shiftKey; });
  window.addEventListener("blur", () => held.clear());
  let lastTick = performance.now();
  setInterval(() => {
    const now = performance.now();
    const dt = Math.min((now - lastTick) / 1000, 0.1);
    lastTick = now;
    if (!held.size) return;
    const axis = (p, n) => (held.has(p) ? 1 : 0) - (held.has(n) ? 1 : 0);
    const k = (fast ? 3 : 1) * dt;
    send({type: "move", forward: SPEED * k * axis("w", "s"), right: SPEED * k * axis("d", "a"),
          up: SPEED * k * axis("e", "q"), yaw: TURN * k * axis("ArrowRight", "ArrowLeft"),
          pitch: TURN * k * axis("ArrowUp", "ArrowDown")});
  }, 25);

  // ---- controls -----------------------------------------------------------------------
  function number(text) {
    const t = String(text).trim();
    return t !== "" && Number.isFinite(Number(t)) ? Number(t) : t;
  }

  $("apply").addEventListener("click", () => {
    const s = live.state || {};
    const changes = {};
    if ($("preset").value !== s.preset) changes.preset = $("preset").value;
    if ($("denoiser").value !== s.denoiser) changes.denoiser = $("denoiser").value;
    if (String(number($("ray_budget").value)) !== String(s.ray_budget)) {
      changes.ray_budget = number($("ray_budget").value);
    }
    if (String(number($("spp").value)) !== String(s.spp)) changes.spp = number($("spp").value);
    $("error").textContent = "";
    if (Object.keys(changes).length) {
      $("rebuild").textContent = "rebuilding…";
      send({type: "settings", ...changes});
    }
  });

  function overlaysChanged() {
    const on = [...document.querySelectorAll("input[data-overlay]")]
      .filter((b) => b.checked).map((b) => b.dataset.overlay);
    send({type: "view", overlays: on});
  }
  for (const box of document.querySelectorAll("input[data-overlay]")) {
    box.addEventListener("change", overlaysChanged);
  }
  $("ov-rings").addEventListener("change", () => { if (live.meta) drawOverlay(live.meta); });
  $("split").addEventListener("change", () => send({type: "view", split: $("split").value}));
  $("fps").addEventListener("change", () => {
    $("error").textContent = "";
    $("rebuild").textContent = "rebuilding…";
    send({type: "settings", fps: Number($("fps").value)});
  });
  $("latency").addEventListener("change", () => {
    $("error").textContent = "";
    send({type: "view", latency_ms: number($("latency").value)});
  });

  function lockChanged() {
    pending = [];
    sentAt.clear();
    send({type: "lock", on: $("lock").checked});
  }
  $("lock").addEventListener("change", lockChanged);

  $("source").addEventListener("change", () => {
    const s = $("source").value;
    if (s === "csv") {
      $("csv-file").hidden = false;
      $("csv-file").click();
    } else {
      $("csv-file").hidden = true;
      send({type: "gaze_source", source: s});
    }
  });
  $("csv-file").addEventListener("change", async () => {
    const f = $("csv-file").files[0];
    if (!f) return;
    $("error").textContent = "";
    send({type: "gaze_source", source: "csv", name: f.name, csv: await f.text()});
  });

  $("record").addEventListener("click", () => {
    const on = !(live.state && live.state.recording);
    $("error").textContent = "";
    send({type: "record", on});
  });

  connect();
})();
