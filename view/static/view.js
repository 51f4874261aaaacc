// haptic-view page: draws the workpiece (blocks in their materials, heights as shade), the
// tool and the handle, force and velocity traces, and the link's state, from the server's
// Server-Sent Events (/events). No external code. window.hapticView exposes counters the
// browser test reads. The page draws only when a frame came (one animation frame asked per
// frame received), so it follows the server's rate down when the view backs off for the
// loops, and an idle page asks the browser for nothing.
"use strict";
(function () {
  const view = window.hapticView = {
    frames: 0, fps: 0, clayVersion: 0, claySumMm: null, claySumInitialMm: null,
    layout: null, last: null, draws: 0, scale: 1,
  };
  const work = document.getElementById("work");
  const wctx = work.getContext("2d");
  const traces = document.getElementById("traces");
  const tctx = traces.getContext("2d");
  const HUES = [28, 200, 300, 120, 50, 260, 0, 160];
  const TRACE_S = 6.0;
  const samples = [];  // [t_s, ft_x, fh_x, v_x_mm_s]
  let heights = null;  // Float32Array mm, rows of y
  let clayImage = null;
  let frameTimes = [];
  let drawPending = false;  // an animation frame is asked for

  function text(id, value) { document.getElementById(id).textContent = value; }
  function fmt(pair, scale, digits, unit) {
    if (!pair) return "-";
    return pair.map(v => v === null ? "-" : (v * scale).toFixed(digits)).join(", ") + " " + unit;
  }

  function decodeClay(clay) {
    const raw = atob(clay.heights_u16_b64);
    const n = raw.length / 2;
    const out = new Float32Array(n);
    let sum = 0;
    for (let i = 0; i < n; i++) {
      const v = raw.charCodeAt(2 * i) | (raw.charCodeAt(2 * i + 1) << 8);
      out[i] = v * 1e-3;  // micrometres -> mm
      sum += out[i];
    }
    view.claySumMm = sum;
    if (view.claySumInitialMm === null) view.claySumInitialMm = sum;
    return out;
  }

  function buildClayImage() {
    const layout = view.layout;
    if (!layout) return;
    const nx = layout.cells_x, ny = layout.cells_y;
    const image = new ImageData(nx, ny);
    let maxH = 0;
    for (const row of layout.initial_heights_mm) for (const h of row) maxH = Math.max(maxH, h);
    maxH = maxH || 1;
    for (let j = 0; j < ny; j++) {
      for (let i = 0; i < nx; i++) {
        const id = layout.block_id[j][i];
        const h = heights ? heights[j * nx + i] : layout.initial_heights_mm[j][i];
        const k = 4 * ((ny - 1 - j) * nx + i);  // y up
        if (id < 0 || h <= 1e-4) {
          image.data[k] = 20; image.data[k + 1] = 22; image.data[k + 2] = 26;
        } else {
          // Shade by height; cut material (below its initial height) loses its colour.
          const hue = HUES[id % HUES.length];
          const initial = layout.initial_heights_mm[j][i];
          const cut = initial > 0 ? Math.min(1, Math.max(0, (initial - h) / initial)) : 0;
          const light = 18 + 50 * Math.min(1, h / maxH);
          const [r, g, b] = hsl(hue, cut > 0.01 ? 0.55 * (1 - 0.8 * Math.sqrt(cut)) : 0.55,
            light / 100);
          image.data[k] = r; image.data[k + 1] = g; image.data[k + 2] = b;
        }
        image.data[k + 3] = 255;
      }
    }
    const canvas = document.createElement("canvas");
    canvas.width = nx; canvas.height = ny;
    canvas.getContext("2d").putImageData(image, 0, 0);
    clayImage = canvas;
  }

  function hsl(h, s, l) {
    const a = s * Math.min(l, 1 - l);
    const f = n => { const k = (n + h / 30) % 12;
      return Math.round(255 * (l - a * Math.max(-1, Math.min(k - 3, 9 - k, 1)))); };
    return [f(0), f(8), f(4)];
  }

  function toCanvas(x, y) {
    const l = view.layout;
    const [x0, x1] = l.x_range_m, [y0, y1] = l.y_range_m;
    return [(x - x0) / (x1 - x0) * work.width, work.height - (y - y0) / (y1 - y0) * work.height];
  }

  function drawWork() {
    wctx.fillStyle = "#0b0d10";
    wctx.fillRect(0, 0, work.width, work.height);
    if (!view.layout) {
      wctx.fillStyle = "#888"; wctx.fillText("waiting for the workpiece...", 20, 20);
      return;
    }
    if (clayImage) {
      wctx.imageSmoothingEnabled = false;
      wctx.drawImage(clayImage, 0, 0, work.width, work.height);
    }
    const f = view.last;
    if (f && f.handle && f.handle.handle_position_m[0] !== null) {
      const [hx, hy] = toCanvas(...f.handle.handle_position_m);
      wctx.strokeStyle = "#8cf"; wctx.lineWidth = 1.5;
      wctx.beginPath(); wctx.moveTo(hx - 10, hy); wctx.lineTo(hx + 10, hy);
      wctx.moveTo(hx, hy - 10); wctx.lineTo(hx, hy + 10); wctx.stroke();
    }
    if (f && f.tool && f.tool.tool_position_m[0] !== null) {
      const [tx, ty] = toCanvas(...f.tool.tool_position_m);
      wctx.fillStyle = f.tool.in_contact ? "#f84" : "#fff";
      wctx.beginPath(); wctx.arc(tx, ty, 6, 0, 2 * Math.PI); wctx.fill();
      const fx = f.tool.tool_force_N[0] || 0, fy = f.tool.tool_force_N[1] || 0;
      wctx.strokeStyle = "#f84"; wctx.lineWidth = 2;
      wctx.beginPath(); wctx.moveTo(tx, ty); wctx.lineTo(tx + 8 * fx, ty - 8 * fy); wctx.stroke();
    }
  }

  function drawTraces() {
    tctx.fillStyle = "#0b0d10";
    tctx.fillRect(0, 0, traces.width, traces.height);
    if (samples.length < 2) return;
    const tEnd = samples[samples.length - 1][0];
    const tStart = tEnd - TRACE_S;
    const w = traces.width, h = traces.height;
    tctx.strokeStyle = "#333"; tctx.beginPath();
    tctx.moveTo(0, h / 2); tctx.lineTo(w, h / 2); tctx.stroke();
    const series = [[1, "#f84", 10], [2, "#8cf", 10], [3, "#8f8", 100]];  // index, colour, range
    for (const [index, colour, range] of series) {
      tctx.strokeStyle = colour; tctx.lineWidth = 1.2; tctx.beginPath();
      let first = true;
      for (const s of samples) {
        if (s[0] < tStart || s[index] === null) continue;
        const x = (s[0] - tStart) / TRACE_S * w;
        const y = h / 2 - s[index] / range * (h / 2);
        if (first) { tctx.moveTo(x, y); first = false; } else tctx.lineTo(x, y);
      }
      tctx.stroke();
    }
    tctx.fillStyle = "#888";
    tctx.fillText("+-10 N, +-100 mm/s, last " + TRACE_S + " s", 8, 14);
  }

  function showStatus(status) {
    const rows = [];
    for (const side of ["master", "slave"]) {
      const s = status[side];
      if (!s) { rows.push(`<tr><td>${side}</td><td class="warn">no status</td></tr>`); continue; }
      const l = s.link || {};
      const wd = l.watchdog_state || "?";
      const cls = wd === "ok" ? "ok" : "bad";
      const ms = v => v === null || v === undefined ? "-" : (v * 1e3).toFixed(3) + " ms";
      rows.push(`<tr><td>${side}</td><td>watchdog <span class="${cls}">${wd}</span>` +
        ` (trips ${l.watchdog_trips})</td></tr>` +
        `<tr><td></td><td>delay p50 ${ms(l.link_one_way_delay_p50_s)}, ` +
        `p99 ${ms(l.link_one_way_delay_p99_s)}</td></tr>` +
        `<tr><td></td><td>loss ${((l.loss_ratio || 0) * 100).toFixed(2)} %, ` +
        `received ${l.link_received}</td></tr>`);
    }
    document.getElementById("link").innerHTML = rows.join("");
    const events = [];
    for (const side of ["master", "slave"]) {
      for (const e of (status[side] && status[side].events) || []) {
        const t = typeof e.time_s === "number" ? e.time_s.toFixed(3) : "?";
        events.push(`${side} ${t} s  ${e.kind}: ${e.reason || ""}`);
      }
    }
    text("events", events.join("\n"));
  }

  function onFrame(f) {
    view.frames += 1;
    view.last = f;
    const now = performance.now();
    frameTimes.push(now);
    while (frameTimes.length && frameTimes[0] < now - 1000) frameTimes.shift();
    view.fps = frameTimes.length;
    view.scale = typeof f.view_scale === "number" ? f.view_scale : 1;
    if (!drawPending) { drawPending = true; requestAnimationFrame(render); }
    if (f.layout) { view.layout = f.layout; showBlocks(f.layout); buildClayImage(); }
    if (f.clay) { heights = decodeClay(f.clay); view.clayVersion = f.clay_version; buildClayImage(); }
    const t = f.tool, h = f.handle;
    if (t || h) {
      samples.push([f.time_ns * 1e-9, t ? t.tool_force_N[0] : null,
        h ? h.handle_force_N[0] : null, t ? t.tool_velocity_m_s[0] * 1e3 : null]);
      while (samples.length && samples[0][0] < f.time_ns * 1e-9 - TRACE_S) samples.shift();
    }
    text("fps", view.scale < 1 ? `${view.fps} (backed off to ${(view.scale * 100).toFixed(1)} %: ` +
      "a loop overruns)" : view.fps);
    text("tpos", fmt(t && t.tool_position_m, 1e3, 2, "mm"));
    text("hpos", fmt(h && h.handle_position_m, 1e3, 2, "mm"));
    text("tforce", fmt(t && t.tool_force_N, 1, 3, "N"));
    text("hforce", fmt(h && h.handle_force_N, 1, 3, "N"));
    text("tvel", fmt(t && t.tool_velocity_m_s, 1e3, 1, "mm/s"));
    text("engage", t ? t.clay_engagement.toFixed(2) : "-");
    text("removed", t ? (t.removed_volume_m3 * 1e6).toFixed(3) + " cm^3" : "-");
    text("clayv", view.clayVersion);
    showStatus(f.status || {});
  }

  function showBlocks(layout) {
    document.getElementById("blocks").innerHTML = layout.block_names.map((name, i) => {
      const [r, g, b] = hsl(HUES[i % HUES.length], 0.55, 0.5);
      return `<span style="color:rgb(${r},${g},${b})">&#9632; ${name} ` +
        `(${layout.block_damping_N_s_per_m[i]} N s/m)</span>`;
    }).join("");
  }

  function render() {
    drawPending = false;
    view.draws += 1;
    drawWork();
    drawTraces();
  }

  const source = new EventSource("/events");
  source.onopen = () => { const c = document.getElementById("conn"); c.textContent = "live";
    c.className = "ok"; };
  source.onerror = () => { const c = document.getElementById("conn");
    c.textContent = "disconnected"; c.className = "bad"; };
  source.onmessage = (event) => onFrame(JSON.parse(event.data));
  drawPending = true;
  requestAnimationFrame(render);  // the empty workpiece until the first frame
})();
