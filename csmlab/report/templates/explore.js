// The interactive part of the csmlab report (see csmlab/report/explore.py for the files it reads).
// Runs from file:// with no server: the run's data comes in <script> files, value planes are
// lossless WebP images decoded by the browser, plots are Plotly's (bundled beside this file).
(function () {
  "use strict";
  const run = window.csmlabRun;
  const kept = window.csmlabKept;
  const MAPS = [
    ["shaded", "shaded view"],
    ["cascade", "cascade index"],
    ["rho", "ρ (texels / pixel)"],
    ["dS", "|ΔS| since previous frame"],
    ["ref", "vs. ray-traced reference"],
  ];
  // A run with [taa] on: each view after TAA beside the one before it.
  if (run.taa) {
    MAPS.splice(1, 0, ["shaded_taa", "shaded after TAA"]);
    MAPS.splice(MAPS.findIndex((m) => m[0] === "dS") + 1, 0, ["dS_taa", "|ΔS| after TAA (less R's)"]);
  }
  const DRAWN_ALONE = new Set(["rho", "dS", "dS_taa"]);
  const CACHE_FRAMES = 48;
  const CASCADE_ALPHA = Math.round(0.45 * 255);
  const DIFF_DARKEN = Math.round(0.65 * 255);
  const $ = (id) => document.getElementById(id);
  const colours = run.colours;
  const methods = [...new Set(run.variants.map((v) => v.method))];
  const points = [...new Set(run.variants.map((v) => v.point))];
  const DASHES = ["solid", "dash", "dot", "dashdot"];
  const state = {
    index: 0,
    shown: new Set(run.variants.map((v) => v.stem)),
    maps: new Set(MAPS.map((m) => m[0])),
    hover: null,
    playing: false,
    data: null,
    view3d: run.variants[0].stem,
  };
  const cache = new Map();
  const pending = new Map();
  const cells = [];

  function rgb(c) { return `rgb(${c[0]},${c[1]},${c[2]})`; }
  function variantColour(v) { return rgb(colours.categories[methods.indexOf(v.method) % colours.categories.length]); }
  function variantDash(v) { return DASHES[points.indexOf(v.point) % DASHES.length]; }
  function cascadeColour(c) { return rgb(colours.categories[c % colours.categories.length]); }

  // ---- frame files -------------------------------------------------------------------------
  // A value plane is a lossless greyscale WebP in base85: decoded from its own bytes (a canvas stays
  // readable, where an image from a file:// address would taint it), without colour conversion or
  // premultiplication, its red channel is the plane's bytes.
  const reader = document.createElement("canvas").getContext("2d", { willReadFrequently: true });

  const B85 = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz!#$%&()*+-;<=>?@^_`{|}~";
  const B85_VALUE = new Uint8Array(128);
  for (let k = 0; k < B85.length; k++) B85_VALUE[B85.charCodeAt(k)] = k;

  // Python's base64.b85decode: 5 characters per 4 bytes, big-endian; a last group of r characters,
  // padded with the largest digit, gives its first r - 1 bytes.
  function base85(text) {
    const n = text.length;
    const out = new Uint8Array(Math.floor(n / 5) * 4 + (n % 5 ? n % 5 - 1 : 0));
    let o = 0;
    for (let g = 0; g < n; g += 5) {
      let v = 0;
      for (let c = g; c < g + 5; c++) v = v * 85 + (c < n ? B85_VALUE[text.charCodeAt(c)] : 84);
      for (let shift = 24; shift >= 0 && o < out.length; shift -= 8) out[o++] = Math.floor(v / 2 ** shift) % 256;
    }
    return out;
  }

  async function planeBytes(text) {
    const bytes = base85(text);
    const bitmap = await createImageBitmap(new Blob([bytes], { type: "image/webp" }),
                                           { colorSpaceConversion: "none", premultiplyAlpha: "none" });
    reader.canvas.width = bitmap.width;
    reader.canvas.height = bitmap.height;
    reader.drawImage(bitmap, 0, 0);
    bitmap.close();
    const rgba = reader.getImageData(0, 0, run.width, run.height).data;
    const plane = new Uint8Array(run.width * run.height);
    for (let k = 0; k < plane.length; k++) plane[k] = rgba[4 * k];
    return plane;
  }

  async function decode(body) {
    const distinct = [];
    for (const uri of body.planes) distinct.push(await planeBytes(uri));
    const out = {};
    for (const stem of Object.keys(body.variants)) {
      const v = body.variants[stem];
      const planes = {};
      run.planes.forEach((name, k) => { planes[name] = distinct[v.planes[k]]; });
      out[stem] = { img: v.img, img_taa: v.img_taa, planes, camera: v.camera, frustum: v.frustum, boxes: v.boxes };
    }
    return out;
  }

  window.csmlabFrame = function (frame, body) {
    const waiting = pending.get(frame);
    if (waiting) {
      pending.delete(frame);
      decode(body).then(waiting.resolve, waiting.reject);
    }
  };

  function load(frame) {
    if (cache.has(frame)) return cache.get(frame);
    const promise = new Promise((resolve, reject) => {
      pending.set(frame, { resolve, reject });
      const script = document.createElement("script");
      script.src = `explore/frames/f${String(frame).padStart(5, "0")}.js`;
      script.onload = () => script.remove();
      script.onerror = () => { script.remove(); reject(new Error(`missing frame file ${script.src}`)); };
      document.head.appendChild(script);
    });
    cache.set(frame, promise);
    while (cache.size > CACHE_FRAMES) cache.delete(cache.keys().next().value);
    return promise;
  }

  // ---- the frame viewer ----------------------------------------------------------------------
  function buildControls() {
    const methodBox = $("explore-methods");
    run.variants.forEach((v) => {
      const label = document.createElement("label");
      const box = document.createElement("input");
      box.type = "checkbox";
      box.checked = true;
      box.dataset.stem = v.stem;
      box.addEventListener("change", () => {
        if (box.checked) state.shown.add(v.stem); else state.shown.delete(v.stem);
        layout();
        updateReadout();
      });
      const swatch = document.createElement("span");
      swatch.className = "swatch";
      swatch.style.background = variantColour(v);
      label.append(box, swatch, " " + v.label);
      methodBox.append(label);
    });
    const mapBox = $("explore-maps");
    MAPS.forEach(([key, title]) => {
      const label = document.createElement("label");
      const box = document.createElement("input");
      box.type = "checkbox";
      box.checked = true;
      box.dataset.map = key;
      box.addEventListener("change", () => {
        if (box.checked) state.maps.add(key); else state.maps.delete(key);
        layout();
      });
      label.append(box, " " + title);
      mapBox.append(label);
    });
    const slider = $("explore-slider");
    slider.max = String(kept.length - 1);
    slider.value = "0";
    slider.addEventListener("input", () => show(Number(slider.value)));
    $("explore-play").addEventListener("click", () => (state.playing ? stop() : play()));
  }

  function buildViewer() {
    const viewer = $("explore-viewer");
    const head = document.createElement("div");
    head.className = "vrow vhead";
    head.append(document.createElement("div"));
    MAPS.forEach(([key, title]) => {
      const h = document.createElement("div");
      h.className = "vtitle";
      h.dataset.map = key;
      h.textContent = title;
      head.append(h);
    });
    viewer.append(head);
    run.variants.forEach((v) => {
      const row = document.createElement("div");
      row.className = "vrow";
      row.dataset.stem = v.stem;
      const name = document.createElement("div");
      name.className = "vlabel";
      name.textContent = v.label;
      row.append(name);
      MAPS.forEach(([key]) => {
        const cell = document.createElement("div");
        cell.className = "vcell";
        cell.dataset.map = key;
        cell.dataset.stem = v.stem;
        // The shaded view under the cascade tint and the reference overlay; ρ and |ΔS| are drawn alone.
        const img = DRAWN_ALONE.has(key) ? null : document.createElement("img");
        if (img) img.alt = `${v.label} ${key}`;
        const canvas = document.createElement("canvas");
        canvas.width = run.width;
        canvas.height = run.height;
        canvas.hidden = key === "shaded" || key === "shaded_taa";
        const mark = document.createElement("div");
        mark.className = "vmark";
        cell.append(...(img ? [img] : []), canvas, mark);
        cell.addEventListener("mousemove", (e) => hover(e, cell));
        row.append(cell);
        cells.push({ stem: v.stem, key, cell, img, canvas, mark });
      });
      viewer.append(row);
    });
    viewer.addEventListener("mouseleave", () => { state.hover = null; updateReadout(); });
    window.addEventListener("resize", layout);
  }

  function layout() {
    const shownMaps = MAPS.filter(([key]) => state.maps.has(key)).length || 1;
    const room = $("explore-viewer").clientWidth - 110 - 6 * shownMaps;
    const width = Math.max(120, Math.min(2 * run.width, Math.floor(room / shownMaps)));
    document.querySelectorAll("#explore-viewer .vrow").forEach((row) => {
      row.hidden = row.dataset.stem !== undefined && !state.shown.has(row.dataset.stem);
    });
    document.querySelectorAll("#explore-viewer [data-map]").forEach((el) => {
      el.hidden = !state.maps.has(el.dataset.map);
      el.style.width = `${width}px`;
    });
    cells.forEach((c) => { c.cell.style.height = `${Math.round(width * run.height / run.width)}px`; });
    placeMarks();
  }

  function paint(canvas, fill) {
    const ctx = canvas.getContext("2d");
    const image = ctx.createImageData(run.width, run.height);
    const px = image.data;
    const n = run.width * run.height;
    for (let k = 0; k < n; k++) fill(k, px, 4 * k);
    ctx.putImageData(image, 0, 0);
  }

  function draw(data) {
    const none = run.no_value;
    cells.forEach(({ stem, key, img, canvas }) => {
      const d = data[stem];
      if (!d) return;
      const p = d.planes;
      if (img) img.src = key === "shaded_taa" ? d.img_taa : d.img;
      if (key === "cascade") {
        paint(canvas, (k, px, o) => {
          const c = p.cascade[k];
          if (c === 255 || p.lit[k] === none) { px[o + 3] = 0; return; }
          const col = colours.categories[c % colours.categories.length];
          px[o] = col[0]; px[o + 1] = col[1]; px[o + 2] = col[2]; px[o + 3] = CASCADE_ALPHA;
        });
      } else if (DRAWN_ALONE.has(key)) {
        const lut = key === "rho" ? colours.rho : colours.dS;
        paint(canvas, (k, px, o) => {
          const code = p[key][k];
          const col = code === none ? colours.no_surface : lut[code];
          px[o] = col[0]; px[o + 1] = col[1]; px[o + 2] = col[2]; px[o + 3] = 255;
        });
      } else if (key === "ref") {
        paint(canvas, (k, px, o) => {
          const diff = p.ref_diff[k];
          if (p.lit[k] === none) { px[o + 3] = 0; return; }
          const col = diff === 1 ? colours.false_shadow : diff === 255 ? colours.false_light : null;
          if (col) { px[o] = col[0]; px[o + 1] = col[1]; px[o + 2] = col[2]; px[o + 3] = 255; }
          else { px[o] = 0; px[o + 1] = 0; px[o + 2] = 0; px[o + 3] = DIFF_DARKEN; }
        });
      }
    });
  }

  async function show(index) {
    state.index = Math.max(0, Math.min(kept.length - 1, index));
    const frame = kept[state.index];
    $("explore-slider").value = String(state.index);
    const t = run.times[run.frames.indexOf(frame)];
    $("explore-frame").textContent = `frame ${frame} · t = ${t.toFixed(2)} s · ${state.index + 1} of ${kept.length}`;
    $("explore-viewer").dataset.frame = "";
    const data = await load(frame);
    if (kept[state.index] !== frame) return;
    state.data = data;
    draw(data);
    $("explore-viewer").dataset.frame = String(frame);
    updateReadout();
    markCurves(frame);
    draw3d();
    markWorld();
    for (let k = 1; k <= 2; k++) if (state.index + k < kept.length) load(kept[state.index + k]);
  }

  function play() {
    state.playing = true;
    $("explore-play").textContent = "❚❚ pause";
    const step = async () => {
      if (!state.playing) return;
      const began = performance.now();
      await show((state.index + 1) % kept.length);
      const wait = Math.max(0, 1000 / run.fps - (performance.now() - began));
      setTimeout(step, wait);
    };
    step();
  }

  function stop() {
    state.playing = false;
    $("explore-play").textContent = "▶ play";
  }

  // ---- hover read-out ------------------------------------------------------------------------
  function hover(event, cell) {
    const box = cell.getBoundingClientRect();
    const i = Math.floor((event.clientX - box.left) / box.width * run.width);
    const j = Math.floor((event.clientY - box.top) / box.height * run.height);
    if (i < 0 || j < 0 || i >= run.width || j >= run.height) return;
    state.hover = { i, j };
    updateReadout();
  }

  function fraction(code) { return code === run.no_value ? "—" : (code / 254).toFixed(3); }
  function rho(code) {
    if (code === run.no_value) return "—";
    const value = Math.pow(2, (code - 127) / run.rho_steps).toPrecision(3);
    return code === 0 ? `≤ ${value}` : code === 254 ? `≥ ${value}` : value;
  }
  const REFERENCE = { 0: "shadowed", 1: "lit" };
  const VERDICT = { 0: "agrees", 1: "false shadow", 255: "false light" };

  function updateReadout() {
    const table = $("explore-readout");
    const where = $("explore-where");
    table.replaceChildren();
    placeMarks();
    if (!state.hover || !state.data) {
      where.textContent = "Point at a pixel of any map to read its values in every shown method.";
      return;
    }
    const { i, j } = state.hover;
    const s = run.stride;
    where.textContent = `pixel x = ${i * s}, y = ${j * s} of the frame` +
      (s === 1 ? "" : ` (shown pixel ${i}, ${j}; one pixel in ${s} along each row and column kept)`);
    const header = document.createElement("tr");
    const heads = run.taa
      ? ["method", "cascade", "ρ (texels/px)", "|ΔS|", "|ΔS| after TAA (less R's)", "lit fraction S", "S after TAA",
         "reference", "reference after TAA", "vs. reference"]
      : ["method", "cascade", "ρ (texels/px)", "|ΔS|", "lit fraction S", "reference", "vs. reference"];
    heads.forEach((h) => {
      const th = document.createElement("th");
      th.textContent = h;
      header.append(th);
    });
    table.append(header);
    const k = j * run.width + i;
    run.variants.filter((v) => state.shown.has(v.stem)).forEach((v) => {
      const p = state.data[v.stem].planes;
      const values = {
        method: v.label,
        cascade: p.cascade[k] === 255 ? "none" : String(p.cascade[k]),
        rho: rho(p.rho[k]),
        dS: fraction(p.dS[k]),
        ...(run.taa ? { dS_taa: fraction(p.dS_taa[k]) } : {}),
        lit: fraction(p.lit[k]),
        ...(run.taa ? { lit_taa: fraction(p.lit_taa[k]) } : {}),
        reference: REFERENCE[p.reference[k]] || "—",
        ...(run.taa ? { reference_taa: fraction(p.reference_taa[k]) } : {}),
        ref_diff: p.lit[k] === run.no_value ? "—" : VERDICT[p.ref_diff[k]],
      };
      const tr = document.createElement("tr");
      tr.dataset.stem = v.stem;
      Object.entries(values).forEach(([key, text]) => {
        const td = document.createElement("td");
        td.dataset.key = key;
        td.textContent = text;
        tr.append(td);
      });
      table.append(tr);
    });
  }

  function placeMarks() {
    cells.forEach(({ cell, mark }) => {
      if (!state.hover) { mark.hidden = true; return; }
      mark.hidden = false;
      mark.style.left = `${(state.hover.i + 0.5) / run.width * 100}%`;
      mark.style.top = `${(state.hover.j + 0.5) / run.height * 100}%`;
    });
  }

  // ---- per-frame curves ----------------------------------------------------------------------
  function buildCurves() {
    const traces = [];
    run.curves.forEach((curve, c) => {
      run.variants.forEach((v) => {
        if (!(curve.key in v.curves)) return;
        traces.push({
          x: run.frames, y: v.curves[curve.key], type: "scatter", mode: "lines+markers",
          name: v.label, legendgroup: v.stem, showlegend: c === 0,
          line: { color: variantColour(v), dash: variantDash(v), width: 1.5 }, marker: { size: 4 },
          xaxis: `x${c + 1}`, yaxis: `y${c + 1}`,
          hovertemplate: `${v.label}<br>frame %{x}<br>${curve.label}: %{y}<extra></extra>`,
        });
      });
    });
    const rows = Math.ceil(run.curves.length / 2);
    const layout = {
      grid: { rows, columns: 2, pattern: "independent" },
      height: 260 * rows, margin: { t: 30, r: 10, b: 40, l: 60 }, hovermode: "closest",
      legend: { orientation: "h", y: 1.08 }, shapes: [], annotations: [],
    };
    run.curves.forEach((curve, c) => {
      layout[`xaxis${c + 1}`] = { title: { text: "frame" } };
      layout[`yaxis${c + 1}`] = { title: { text: curve.label } };
      layout.shapes.push({ type: "line", xref: `x${c + 1}`, yref: `y${c + 1} domain`, x0: kept[0], x1: kept[0],
                           y0: 0, y1: 1, line: { color: "#b34700", width: 1.5 } });
    });
    Plotly.newPlot("explore-curves", traces, layout, { responsive: true, displaylogo: false });
    $("explore-curves").on("plotly_click", (event) => {
      if (!event.points.length) return;
      stop();
      show(nearestKept(event.points[0].x));
    });
  }

  function nearestKept(frame) {
    let best = 0;
    kept.forEach((f, k) => { if (Math.abs(f - frame) < Math.abs(kept[best] - frame)) best = k; });
    return best;
  }

  function markCurves(frame) {
    const update = {};
    run.curves.forEach((_, c) => { update[`shapes[${c}].x0`] = frame; update[`shapes[${c}].x1`] = frame; });
    Plotly.relayout("explore-curves", update);
  }

  // ---- 3D view -------------------------------------------------------------------------------
  function lines(corners, edges) {
    const x = [], y = [], z = [];
    edges.forEach(([a, b]) => {
      x.push(corners[a][0], corners[b][0], null);
      y.push(corners[a][1], corners[b][1], null);
      z.push(corners[a][2], corners[b][2], null);
    });
    return { x, y, z };
  }

  function build3d() {
    const select = $("explore-3d-method");
    run.variants.forEach((v) => {
      const option = document.createElement("option");
      option.value = v.stem;
      option.textContent = v.label;
      select.append(option);
    });
    select.addEventListener("change", () => { state.view3d = select.value; draw3d(); });
  }

  function draw3d() {
    if (!state.data) return;
    const d = state.data[state.view3d];
    const traces = [{
      type: "scatter3d", mode: "markers", name: "casters (sampled)",
      x: run.casters.map((p) => p[0]), y: run.casters.map((p) => p[2]), z: run.casters.map((p) => p[1]),
      marker: { size: 1.5, color: "#9a9a9a" }, hoverinfo: "skip",
    }, {
      type: "scatter3d", mode: "markers", name: "camera",
      x: [d.camera[0]], y: [d.camera[2]], z: [d.camera[1]], marker: { size: 5, color: "#000" },
    }];
    for (let c = 0; c < run.cascades; c++) {
      const slice = lines(d.frustum[c], run.frustum_edges);
      const box = lines(d.boxes[c], run.box_edges);
      traces.push({ type: "scatter3d", mode: "lines", name: `cascade ${c}`, legendgroup: `c${c}`,
                    x: slice.x, y: slice.z, z: slice.y, line: { color: cascadeColour(c), width: 2 },
                    hovertemplate: `cascade ${c}: frustum slice<extra></extra>` });
      traces.push({ type: "scatter3d", mode: "lines", name: `cascade ${c} box`, legendgroup: `c${c}`,
                    showlegend: false, x: box.x, y: box.z, z: box.y, line: { color: cascadeColour(c), width: 6 },
                    hovertemplate: `cascade ${c}: light-space box<extra></extra>` });
    }
    const layout = {
      height: 600, margin: { t: 10, r: 10, b: 10, l: 10 }, uirevision: "keep",
      legend: { title: { text: "click: show / hide" } },
      scene: { aspectmode: "data", xaxis: { title: { text: "x (m)" } }, yaxis: { title: { text: "z (m)" } },
               zaxis: { title: { text: "y, up (m)" } }, camera: { eye: { x: -1.3, y: -1.3, z: 0.9 } } },
    };
    Plotly.react("explore-3d", traces, layout, { responsive: true, displaylogo: false });
  }

  // ---- whole-run maps ------------------------------------------------------------------------
  function percentile(values, q) {
    const finite = values.flat().filter((v) => v !== null).sort((a, b) => a - b);
    return finite.length ? finite[Math.min(finite.length - 1, Math.floor(q * finite.length))] : 1;
  }

  // Viridis on the square-root scale of the |ΔS| maps, as Plotly colour-scale stops.
  const SQRT_VIRIDIS = Array.from({ length: 33 }, (_, k) => [k / 32, rgb(colours.dS[Math.round(254 * k / 32)])]);

  function extent(axis, counted, along) {
    // The range of cells that some pixel fell in, half a cell beyond: the map zooms on where the run looked.
    const hit = [];
    counted.forEach((row, r) => row.forEach((c, k) => { if (c > 0) hit.push(along === "x" ? k : r); }));
    if (!hit.length) return undefined;
    const half = run.world.cell / 2;
    return [axis[Math.min(...hit)] - half, axis[Math.max(...hit)] + half];
  }

  function buildWorld() {
    const n = run.variants.length;
    const rows = [["mean_dS", "mean |ΔS|", "coloraxis"], ["flip_rate", "flip rate (%)", "coloraxis2"]];
    const traces = [];
    const layout = {
      grid: { rows: 2, columns: n, pattern: "independent", ygap: 0.25 }, height: 360 * 2 + 40,
      margin: { t: 40, r: 10, b: 40, l: 50 }, showlegend: false, annotations: [],
      coloraxis: { colorscale: SQRT_VIRIDIS, cmin: 0,
                   cmax: percentile(run.variants.map((v) => v.world.mean_dS), 0.99) || 1,
                   colorbar: { title: { text: "mean |ΔS|" }, y: 0.8, len: 0.4 } },
      coloraxis2: { colorscale: SQRT_VIRIDIS, cmin: 0,
                    cmax: percentile(run.variants.map((v) => v.world.flip_rate), 0.99) || 1,
                    colorbar: { title: { text: "flips (%)" }, y: 0.2, len: 0.4 } },
    };
    const counted = run.variants[0].world.counted;
    const xRange = extent(run.world.x, counted, "x");
    const zRange = extent(run.world.z, counted, "z");
    rows.forEach(([key, title, axis], r) => {
      run.variants.forEach((v, c) => {
        const a = r * n + c + 1;
        traces.push({
          type: "heatmap", x: run.world.x, y: run.world.z, z: v.world[key], coloraxis: axis,
          customdata: v.world.counted, xaxis: `x${a}`, yaxis: `y${a}`,
          hovertemplate: `${v.label}<br>x %{x} m, z %{y} m<br>${title}: %{z}<br>samples: %{customdata}<extra></extra>`,
        });
        traces.push({ type: "scatter", mode: "lines", x: v.path.map((p) => p[0]), y: v.path.map((p) => p[1]),
                      line: { color: "#fff", width: 1 }, xaxis: `x${a}`, yaxis: `y${a}`, hoverinfo: "skip" });
        traces.push({ type: "scatter", mode: "markers", x: [v.path[0][0]], y: [v.path[0][1]], name: "camera",
                      marker: { color: "#d55e00", size: 9, line: { color: "#fff", width: 1 } },
                      xaxis: `x${a}`, yaxis: `y${a}`, hoverinfo: "skip" });
        layout[`xaxis${a}`] = { title: { text: "x (m)" }, constrain: "domain", range: xRange };
        layout[`yaxis${a}`] = { title: { text: c === 0 ? "z (m), top-down" : "" }, scaleanchor: `x${a}`,
                                range: zRange && [zRange[1], zRange[0]], constrain: "domain" };
        layout.annotations.push({ text: `<b>${v.label}</b>: ${title}`, showarrow: false, xref: `x${a} domain`,
                                  yref: `y${a} domain`, x: 0.5, y: 1.0, yanchor: "bottom", font: { size: 12 } });
      });
    });
    Plotly.newPlot("explore-world", traces, layout, { responsive: true, displaylogo: false });
  }

  function markWorld() {
    const gd = $("explore-world");
    if (!gd.data) return;
    const at = run.frames.indexOf(kept[state.index]);
    const markers = [], x = [], y = [];
    gd.data.forEach((trace, k) => {
      if (trace.name === "camera") {
        const v = run.variants[Math.floor(k / 3) % run.variants.length];
        markers.push(k); x.push([v.path[at][0]]); y.push([v.path[at][1]]);
      }
    });
    Plotly.restyle(gd, { x, y }, markers);
  }

  function buildRho() {
    const traces = [];
    const n = run.variants.length;
    const layout = { grid: { rows: 1, columns: n, pattern: "independent" }, height: 340,
                     margin: { t: 40, r: 10, b: 50, l: 60 }, shapes: [], annotations: [] };
    run.variants.forEach((v, c) => {
      v.rho_hist.forEach((counts, k) => {
        const total = counts.reduce((a, b) => a + b, 0);
        if (!total) return;
        traces.push({
          type: "scatter", mode: "lines", line: { shape: "hvh", color: cascadeColour(k), width: 1.5 },
          x: run.rho_centres, y: counts.map((x) => 100 * x / total), name: `cascade ${k}`,
          legendgroup: `c${k}`, showlegend: c === 0, xaxis: `x${c + 1}`, yaxis: `y${c + 1}`,
          hovertemplate: `${v.label}, cascade ${k}<br>ρ %{x:.3g}: %{y:.2f} % of its pixels<extra></extra>`,
        });
      });
      layout[`xaxis${c + 1}`] = { type: "log", title: { text: "ρ (texels / pixel)" } };
      layout[`yaxis${c + 1}`] = { title: { text: c === 0 ? "% of the cascade's pixels" : "" } };
      layout.shapes.push({ type: "line", xref: `x${c + 1}`, yref: `y${c + 1} domain`, x0: 1, x1: 1, y0: 0, y1: 1,
                           line: { color: "#555", dash: "dot", width: 1 } });
      layout.annotations.push({ text: v.label, showarrow: false, xref: `x${c + 1} domain`, yref: `y${c + 1} domain`,
                                x: 0.5, y: 1.1 });
    });
    Plotly.newPlot("explore-rho", traces, layout, { responsive: true, displaylogo: false });
  }

  buildControls();
  buildViewer();
  layout();
  buildCurves();
  build3d();
  buildWorld();
  buildRho();
  show(0);
})();
