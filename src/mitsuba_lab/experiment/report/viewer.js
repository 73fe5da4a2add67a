/* mitsuba_lab sweep report: the comparison viewer (see viewer.py for the data it reads).
 *
 * Every .viewer element carries its data as JSON: renders as base64 little-endian half floats
 * (linear RGB), the error and variance maps as half-float log10 values. All drawing happens
 * here: exposure and the sRGB curve for images, a colour map for the maps, and one view
 * (zoom, pan) shared by every image of a viewer. The signed difference map is computed here
 * from a render and the reference (viewer.py signed_difference, the same formula). The split
 * view draws strategy A left of a divider and strategy B right of it, in the current mode.
 * Keys act on the viewer under the mouse or holding the focus, so the page still scrolls with
 * the arrow keys elsewhere.
 */
(function () {
  "use strict";
  const MAX_SIDE = 512;       // the image area's longer side in CSS pixels
  const CROP_BOX = [112, 64]; // a crop is enlarged to fit this box
  const DIVIDER_GRAB = 6;      // CSS pixels either side of the split view's divider that grab it
  const MODES = { e: "err", d: "diff", v: "var" };
  const MODE_NAMES = { err: "log10 relative error |x - ref| / sqrt(ref^2 + 0.01)",
                       diff: "signed difference (x - ref) / sqrt(ref^2 + 0.01), channels averaged: " +
                             "red brighter than the reference (over-estimates), blue darker (under-estimates)",
                       var: "log10 per-pixel variance across seeds / (ref^2 + 0.01)" };
  const REF = "ref";           // the reference's image key (viewer.py)

  // Every half-float bit pattern decoded once.
  const HALF = new Float32Array(65536);
  for (let h = 0; h < 65536; h++) {
    const sign = h & 0x8000 ? -1 : 1, e = (h >> 10) & 31, m = h & 1023;
    HALF[h] = e === 0 ? sign * m * 2 ** -24
      : e === 31 ? (m ? NaN : sign * Infinity) : sign * (1 + m / 1024) * 2 ** (e - 15);
  }

  function decodeHalf(b64) {
    const raw = atob(b64), view = new DataView(new ArrayBuffer(raw.length));
    for (let i = 0; i < raw.length; i++) view.setUint8(i, raw.charCodeAt(i));
    const out = new Float32Array(raw.length / 2);
    for (let i = 0; i < out.length; i++) out[i] = HALF[view.getUint16(2 * i, true)];
    return out;
  }

  // Linear radiance to an 8-bit sRGB level (IEC 61966-2-1); NaN and negatives give 0.
  function srgb(v) {
    v = v > 0 ? (v < 1 ? v : 1) : 0;
    return Math.round(255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055));
  }

  function colourTable(stops) {
    const lut = new Uint8ClampedArray(256 * 3);
    for (let i = 0; i < 256; i++) {
      const x = i / 255 * (stops.length - 1), k = Math.min(Math.floor(x), stops.length - 2), f = x - k;
      for (let c = 0; c < 3; c++) lut[3 * i + c] = stops[k][c] * (1 - f) + stops[k + 1][c] * f;
    }
    return lut;
  }

  function el(tag, props, ...children) {
    const node = Object.assign(document.createElement(tag), props || {});
    for (const child of children) node.append(child);
    return node;
  }

  class Viewer {
    constructor(root) {
      const d = this.data = JSON.parse(root.querySelector(".vw-data").textContent);
      this.root = root;
      this.decoded = {};
      this.set = d.start;
      this.entry = 0;
      this.mode = "image";
      this.exposure = 0;
      this.showRegions = true;
      this.hover = false;
      this.split = false;          // split view: entry A (this.entry) left of the divider, splitB right
      this.splitB = 0;
      this.divider = 0.5;          // the divider's place, a fraction of the canvas width
      this.luts = {};
      for (const [mode, stops] of Object.entries(d.colormaps)) this.luts[mode] = colourTable(stops);
      const fit = Math.min(MAX_SIDE / d.width, MAX_SIDE / d.height);
      this.fit = fit >= 1 ? Math.floor(fit) : fit;        // whole screen pixels per image pixel
      this.build();
      this.resetView();
      this.selectSet(this.set);
    }

    pixels(key) {
      return this.decoded[key] || (this.decoded[key] = decodeHalf(this.data.images[key]));
    }

    // The signed difference map of an entry, computed once from its render and the reference.
    signed(entry) {
      const key = entry.rgb + ":diff";
      if (!this.decoded[key]) {
        const x = this.pixels(entry.rgb), r = this.pixels(REF), out = new Float32Array(x.length / 3);
        for (let i = 0; i < out.length; i++) {
          let sum = 0;
          for (let c = 0; c < 3; c++) {
            const ref = r[3 * i + c];
            sum += (x[3 * i + c] - ref) / Math.sqrt(ref * ref + 0.01);
          }
          out[i] = sum / 3;
        }
        this.decoded[key] = out;
      }
      return this.decoded[key];
    }

    mapValues(entry, mode) {
      return mode === "diff" ? this.signed(entry) : this.pixels(entry[mode]);
    }

    entries() { return this.data.sets[this.set].entries; }

    // Indices of the strategies of the current comparison (entry 0 is the reference).
    strategies() { return this.entries().map((e, k) => k).filter(k => k > 0); }

    // -- the page elements ------------------------------------------------------------
    build() {
      const d = this.data, root = this.root;
      this.setRow = el("div", { className: "vw-row" }, "compare: ");
      d.sets.forEach((s, i) => this.setRow.append(
        el("button", { textContent: s.name, onclick: () => this.selectSet(i) })));
      this.labelRow = el("div", { className: "vw-row vw-labels" });
      this.canvas = el("canvas", { className: "vw-canvas", width: Math.round(d.width * this.fit),
                                   height: Math.round(d.height * this.fit) });
      this.crops = el("table", { className: "vw-crops" });
      this.off = el("canvas", { width: d.width, height: d.height });
      this.slider = el("input", { type: "range", min: -10, max: 10, step: 0.1, value: 0,
                                  className: "vw-exposure", oninput: () => this.setExposure(+this.slider.value) });
      this.expText = el("span", { className: "vw-ev", textContent: "+0.0 EV" });
      this.toggles = {};
      const toggle = (mode, text) => {
        const box = el("input", { type: "checkbox", className: "vw-" + mode,
                                  onchange: () => this.setMode(box.checked ? mode : "image") });
        this.toggles[mode] = box;
        return el("label", {}, box, " " + text);
      };
      const regions = el("input", { type: "checkbox", checked: true, className: "vw-regions",
                                    onchange: () => { this.showRegions = regions.checked; this.draw(); } });
      this.splitBox = el("input", { type: "checkbox", className: "vw-split-on",
                                    onchange: () => this.setSplit(this.splitBox.checked) });
      this.sideA = el("select", { className: "vw-side-a", title: "left of the divider",
                                  onchange: () => this.select(+this.sideA.value) });
      this.sideB = el("select", { className: "vw-side-b", title: "right of the divider",
                                  onchange: () => this.setB(+this.sideB.value) });
      this.dividerSlider = el("input", { type: "range", min: 0, max: 100, step: 1, value: 50, className: "vw-divider",
                                         title: "the divider's place",
                                         oninput: () => this.setDivider(this.dividerSlider.value / 100) });
      this.splitNote = el("span", { className: "vw-help vw-split-note" });
      this.legend = el("span", { className: "vw-legend" });
      this.legend.style.display = "none";
      this.legendText = el("span", { className: "vw-help" });
      this.status = el("div", { className: "vw-status" });
      this.readout = el("div", { className: "vw-status" });
      root.append(this.setRow, this.labelRow,
        el("div", { className: "vw-body" }, this.canvas, this.crops),
        el("div", { className: "vw-row" }, "exposure ", this.slider, this.expText,
           toggle("err", "relative error (e)"), toggle("diff", "signed difference (d)"), toggle("var", "variance (v)"),
           el("label", {}, regions, " regions (r)"),
           el("button", { textContent: "reset view (0)", onclick: () => { this.resetView(); this.draw(); } }),
           this.legend, this.legendText),
        el("div", { className: "vw-row vw-split" }, el("label", {}, this.splitBox, " split view (s): "),
           "left A ", this.sideA, " right B ", this.sideB, " divider ", this.dividerSlider, this.splitNote),
        this.status, this.readout,
        el("div", { className: "vw-help", textContent: "keys (mouse over the viewer): 1-9 or \u2190 \u2192 " +
          "image, \u2191 \u2193 comparison, e error map, d signed difference, v variance, r regions, " +
          "+ - exposure, 0 reset view; s split view, then 1-9 or \u2190 \u2192 pick A (left), b steps B " +
          "(right), [ ] move the divider; wheel zooms, drag pans (drag the divider to move it), " +
          "double-click resets" }));
      this.listen();
    }

    listen() {
      const c = this.canvas;
      this.root.addEventListener("mouseenter", () => { this.hover = true; this.root.classList.add("vw-hover"); });
      this.root.addEventListener("mouseleave", () => { this.hover = false; this.root.classList.remove("vw-hover"); });
      c.addEventListener("wheel", ev => {
        ev.preventDefault();
        const r = c.getBoundingClientRect();
        this.zoom(Math.exp(-ev.deltaY * 0.0015), ev.clientX - r.left, ev.clientY - r.top);
      }, { passive: false });
      c.addEventListener("mousedown", ev => {
        if (this.nearDivider(ev)) { this.dragDivider = true; return; }
        this.drag = [ev.clientX, ev.clientY];
        c.style.cursor = "grabbing";
      });
      window.addEventListener("mouseup", () => { this.drag = null; this.dragDivider = false; c.style.cursor = ""; });
      window.addEventListener("mousemove", ev => {
        if (this.dragDivider) {
          const r = c.getBoundingClientRect();
          this.setDivider((ev.clientX - r.left) / r.width);
          return;
        }
        if (!this.drag) return;
        this.view.x += ev.clientX - this.drag[0];
        this.view.y += ev.clientY - this.drag[1];
        this.drag = [ev.clientX, ev.clientY];
        this.draw();
      });
      c.addEventListener("mousemove", ev => {
        this.pointer = ev;
        if (!this.drag) c.style.cursor = this.dragDivider || this.nearDivider(ev) ? "ew-resize" : "";
        this.showPixel();
      });
      c.addEventListener("dblclick", () => { this.resetView(); this.draw(); });
    }

    // -- state changes ----------------------------------------------------------------
    selectSet(i) {
      const n = this.data.sets.length, key = this.entries()[this.entry]?.key;
      const keyB = this.entries()[this.splitB]?.key;
      this.set = ((i % n) + n) % n;
      const same = this.entries().findIndex(e => e.key === key);   // keep the strategy shown (its label may carry a mark)
      this.entry = same >= 0 ? same : Math.min(this.entry, this.entries().length - 1);
      this.splitB = this.entries().findIndex(e => e.key === keyB);
      [...this.setRow.querySelectorAll("button")].forEach((b, k) => b.classList.toggle("vw-on", k === this.set));
      this.labelRow.replaceChildren(...this.entries().map((e, k) => el("button", {
        textContent: `${k + 1} ${e.label}`, title: e.detail, onclick: () => this.select(k) })));
      const options = () => this.strategies().map(k => el("option", { value: k, textContent: this.entries()[k].label }));
      this.sideA.replaceChildren(...options());
      this.sideB.replaceChildren(...options());
      this.buildCrops();
      this.setSplit(this.split, false);
      this.select(this.entry);
    }

    select(k) {
      const n = this.entries().length;
      k = ((k % n) + n) % n;
      if (this.split && k === 0) {
        this.splitNote.textContent = "the split view compares two strategies: the reference is no side (s leaves it)";
        return;
      }
      if (this.split && k === this.splitB) this.splitB = this.entry;   // picking B as A swaps the sides
      this.entry = k;
      this.refreshLabels();
      this.update();
    }

    // B, the strategy right of the divider.
    setB(k) {
      if (!this.split || k < 1 || k >= this.entries().length) return;
      if (k === this.entry) this.entry = this.splitB;                  // picking A as B swaps the sides
      this.splitB = k;
      this.refreshLabels();
      this.update();
    }

    // The split view on or off; it needs two strategies in the comparison shown.
    setSplit(on, redraw = true) {
      const strategies = this.strategies(), possible = strategies.length >= 2;
      this.split = on && possible;
      this.splitBox.checked = this.split;
      this.splitBox.disabled = !possible;
      for (const input of [this.sideA, this.sideB, this.dividerSlider]) input.disabled = !this.split;
      this.splitNote.textContent = possible ? "" : `the split view needs two strategies; ` +
        `this comparison has ${strategies.length === 1 ? "one" : "none"}`;
      if (this.split) {
        if (this.entry === 0) this.entry = strategies[0];
        if (!(this.splitB > 0) || this.splitB === this.entry)
          this.splitB = strategies.find(k => k !== this.entry);
      }
      if (redraw) { this.refreshLabels(); this.update(); }
    }

    setDivider(fraction) {
      this.divider = Math.max(0, Math.min(1, fraction));
      this.dividerSlider.value = Math.round(this.divider * 100);
      this.draw();
    }

    refreshLabels() {
      const e = this.entries(), a = e[this.entry], name = this.data.sets[this.set].name;
      [...this.labelRow.children].forEach((b, j) => {
        b.classList.toggle("vw-on", j === this.entry);
        b.classList.toggle("vw-b", this.split && j === this.splitB);
        b.disabled = this.split && j === 0;
      });
      if (this.split) {
        this.sideA.value = this.entry;
        this.sideB.value = this.splitB;
        this.splitNote.textContent = `left of the divider: A ${a.label}; right: B ${e[this.splitB].label}`;
        this.status.textContent = `${name} \u2014 A (left) ${a.detail} | B (right) ${e[this.splitB].detail}`;
      } else {
        this.status.textContent = `${name} \u2014 ${a.detail}`;
      }
    }

    setMode(mode) {
      this.mode = mode;
      for (const [m, box] of Object.entries(this.toggles)) box.checked = m === mode;
      const on = mode !== "image";
      this.legend.style.display = on ? "" : "none";
      if (on) {
        const stops = this.data.colormaps[mode].map(c => `rgb(${c})`).join(",");
        const [lo, hi] = this.data[mode + "_range"];
        this.legend.style.background = `linear-gradient(to right, ${stops})`;
        const plus = mode === "diff" && hi > 0 ? "+" : "";
        this.legendText.textContent = `${lo} \u2026 ${plus}${hi}: ${MODE_NAMES[mode]}`;
      } else {
        this.legendText.textContent = "";
      }
      this.update();
    }

    setExposure(value) {
      this.exposure = Math.max(-10, Math.min(10, Math.round(value * 10) / 10));
      this.slider.value = this.exposure;
      this.expText.textContent = `${this.exposure >= 0 ? "+" : ""}${this.exposure.toFixed(1)} EV`;
      this.update();
    }

    resetView() {
      this.view = { s: this.fit, x: 0, y: 0 };
    }

    zoom(factor, cx, cy) {
      const v = this.view, s = Math.max(this.fit / 2, Math.min(this.fit * 64, v.s * factor));
      v.x = cx - (cx - v.x) * (s / v.s);       // the image point under the cursor stays put
      v.y = cy - (cy - v.y) * (s / v.s);
      v.s = s;
      this.draw();
    }

    key(k) {
      if (k >= "1" && k <= "9" && k.length === 1) {
        if (+k <= this.entries().length) this.select(+k - 1);
      } else if (k === "ArrowRight" || k === "ArrowLeft") {
        const step = k === "ArrowRight" ? 1 : -1, n = this.entries().length;
        let next = this.entry + step;
        if (this.split && ((next % n) + n) % n === 0) next += step;      // the reference is no side
        this.select(next);
      } else if (k === "s") {
        this.setSplit(!this.split);
      } else if (k === "b") {
        const s = this.strategies(), i = s.indexOf(this.splitB);
        let next = s[(i + 1) % s.length];
        if (next === this.entry && s.length > 2) next = s[(i + 2) % s.length];   // two: b swaps them
        this.setB(next);
      } else if (k === "[" || k === "]") {
        this.setDivider(this.divider + (k === "]" ? 0.05 : -0.05));
      } else if (k === "ArrowDown" || k === "ArrowUp") {
        this.selectSet(this.set + (k === "ArrowDown" ? 1 : -1));
      } else if (k in MODES) {
        this.setMode(this.mode === MODES[k] ? "image" : MODES[k]);
      } else if (k === "r") {
        this.showRegions = !this.showRegions;
        this.root.querySelector(".vw-regions").checked = this.showRegions;
        this.draw();
      } else if (k === "+" || k === "=" || k === "-") {
        this.setExposure(this.exposure + (k === "-" ? -0.5 : 0.5));
      } else if (k === "0") {
        this.resetView();
        this.draw();
      } else {
        return false;
      }
      return true;
    }

    // -- drawing ----------------------------------------------------------------------
    // One rectangle of an entry as 8-bit RGBA: exposure (plus a crop's own offset) and sRGB,
    // or the mode's colour map.
    toneMap(entry, x0, y0, w, h, offset = 0) {
      const d = this.data, out = new ImageData(w, h), px = out.data, image = this.mode === "image";
      const src = image ? this.pixels(entry.rgb) : this.mapValues(entry, this.mode), k = 2 ** (this.exposure + offset);
      const lut = this.luts[this.mode], [lo, hi] = d[this.mode + "_range"] || [0, 1];
      for (let y = 0; y < h; y++) {
        for (let x = 0; x < w; x++) {
          const i = (y0 + y) * d.width + x0 + x, o = 4 * (y * w + x);
          if (image) {
            for (let c = 0; c < 3; c++) px[o + c] = srgb(src[3 * i + c] * k);
          } else {
            const t = 3 * (Math.round(255 * Math.min(Math.max((src[i] - lo) / (hi - lo), 0), 1)) || 0);
            px[o] = lut[t]; px[o + 1] = lut[t + 1]; px[o + 2] = lut[t + 2];
          }
          px[o + 3] = 255;
        }
      }
      return out;
    }

    update() {
      const d = this.data;
      this.off.getContext("2d").putImageData(this.toneMap(this.entries()[this.entry], 0, 0, d.width, d.height), 0, 0);
      if (this.split) {
        this.offB = this.offB || el("canvas", { width: d.width, height: d.height });
        this.offB.getContext("2d").putImageData(this.toneMap(this.entries()[this.splitB], 0, 0, d.width, d.height), 0, 0);
      }
      this.draw();
      this.drawCrops();
    }

    // The divider's canvas column: canvas pixels left of it show A, the others B.
    dividerX() { return Math.round(this.divider * this.canvas.width); }

    nearDivider(ev) {
      if (!this.split) return false;
      const r = this.canvas.getBoundingClientRect();
      return Math.abs(ev.clientX - r.left - this.dividerX() * r.width / this.canvas.width) <= DIVIDER_GRAB;
    }

    draw() {
      const ctx = this.canvas.getContext("2d"), v = this.view, W = this.canvas.width, H = this.canvas.height;
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.fillStyle = "#222";
      ctx.fillRect(0, 0, W, H);
      ctx.imageSmoothingEnabled = false;
      const xd = this.dividerX();
      const layers = this.split ? [[this.off, 0, xd], [this.offB, xd, W]] : [[this.off, 0, W]];
      for (const [image, x0, x1] of layers) {
        ctx.save();
        ctx.beginPath();
        ctx.rect(x0, 0, x1 - x0, H);
        ctx.clip();
        ctx.setTransform(v.s, 0, 0, v.s, v.x, v.y);
        ctx.drawImage(image, 0, 0);
        ctx.restore();
      }
      this.showPixel();
      if (this.showRegions) {
        ctx.strokeStyle = "cyan";
        ctx.fillStyle = "cyan";
        ctx.font = "11px sans-serif";
        for (const [name, [x0, y0, x1, y1]] of Object.entries(this.data.regions)) {
          ctx.strokeRect(v.x + x0 * v.s - 0.5, v.y + y0 * v.s - 0.5, (x1 - x0) * v.s + 1, (y1 - y0) * v.s + 1);
          ctx.fillText(name, v.x + x0 * v.s, v.y + y0 * v.s - 3);
        }
      }
      if (this.split) this.drawDivider(ctx, xd, W, H);
    }

    // The divider (a line with a handle) and, beside it at the bottom, which side is which.
    drawDivider(ctx, xd, W, H) {
      ctx.fillStyle = "rgba(0, 0, 0, 0.6)";
      ctx.fillRect(xd - 2, 0, 4, H);
      ctx.fillStyle = "#fff";
      ctx.fillRect(xd - 1, 0, 2, H);
      ctx.beginPath();
      ctx.arc(xd, H / 2, 7, 0, 2 * Math.PI);
      ctx.fill();
      ctx.fillStyle = "#222";
      ctx.font = "10px sans-serif";
      ctx.textAlign = "center";
      ctx.textBaseline = "middle";
      ctx.fillText("\u2194", xd, H / 2);
      const e = this.entries(), tags = [[`\u25c0 A ${e[this.entry].label}`, "#2a7ae2", -1],
                                         [`B ${e[this.splitB].label} \u25b6`, "#e2762a", 1]];
      ctx.font = "12px sans-serif";
      ctx.textAlign = "left";
      for (const [text, colour, side] of tags) {
        const w = ctx.measureText(text).width + 10, h = 18;
        let x = side < 0 ? xd - 8 - w : xd + 8;
        x = Math.max(2, Math.min(W - w - 2, x));
        ctx.fillStyle = colour;
        ctx.fillRect(x, H - h - 4, w, h);
        ctx.fillStyle = "#fff";
        ctx.fillText(text, x + 5, H - h / 2 - 4);
      }
      ctx.textBaseline = "alphabetic";
    }

    // The crops table: a row per image of the comparison, a column per region.
    buildCrops() {
      const regions = Object.entries(this.data.regions);
      this.cropCells = [];
      if (!regions.length) { this.crops.replaceChildren(); return; }
      const offsets = this.data.crop_exposure;
      const head = el("tr", {}, el("th"), ...regions.map(([name]) => el("th", {
        textContent: offsets[name] ? `${name} (${offsets[name] > 0 ? "+" : ""}${offsets[name]} EV)` : name })));
      const rows = this.entries().map((e, k) => {
        const cells = regions.map(([name, [x0, y0, x1, y1]]) => {
          const w = x1 - x0, h = y1 - y0, fit = Math.min(CROP_BOX[0] / w, CROP_BOX[1] / h);
          const s = fit >= 1 ? Math.floor(fit) : fit;
          const canvas = el("canvas", { width: w, height: h });
          canvas.style.width = `${Math.round(w * s)}px`;
          canvas.style.height = `${Math.round(h * s)}px`;
          this.cropCells.push([e, canvas, x0, y0, w, h, offsets[name] || 0]);
          return el("td", {}, canvas, el("div", { textContent: e.crops[name].text }));
        });
        const row = el("tr", { onclick: () => this.select(k) },
                       el("th", { textContent: `${k + 1} ${e.label}` }), ...cells);
        row.style.cursor = "pointer";
        return row;
      });
      this.crops.replaceChildren(head, ...rows);
    }

    drawCrops() {
      for (const [e, canvas, x0, y0, w, h, offset] of this.cropCells) {
        canvas.getContext("2d").putImageData(this.toneMap(e, x0, y0, w, h, offset), 0, 0);
        canvas.parentNode.classList.toggle("vw-on", e === this.entries()[this.entry]);
        canvas.parentNode.classList.toggle("vw-b", this.split && e === this.entries()[this.splitB]);
      }
    }

    showPixel() {
      const ev = this.pointer;
      if (!ev) return;
      const r = this.canvas.getBoundingClientRect(), v = this.view, d = this.data;
      const x = Math.floor((ev.clientX - r.left - v.x) / v.s), y = Math.floor((ev.clientY - r.top - v.y) / v.s);
      if (x < 0 || y < 0 || x >= d.width || y >= d.height) { this.readout.textContent = ""; return; }
      const right = this.split && (ev.clientX - r.left) * this.canvas.width / r.width >= this.dividerX();
      const e = this.entries()[right ? this.splitB : this.entry], i = y * d.width + x, rgb = this.pixels(e.rgb);
      const f = n => n.toPrecision(3), diff = this.signed(e)[i];
      this.readout.textContent = (this.split ? `${right ? "B" : "A"} ${e.label}, ` : "") +
        `pixel (${x}, ${y}): RGB ${f(rgb[3 * i])} ${f(rgb[3 * i + 1])} ${f(rgb[3 * i + 2])}, ` +
        `relative error 10^${this.pixels(e.err)[i].toFixed(2)}, signed difference ${diff >= 0 ? "+" : ""}${f(diff)}, ` +
        `variance 10^${this.pixels(e.var)[i].toFixed(2)}`;
    }
  }

  const viewers = [];
  document.addEventListener("keydown", ev => {
    if (ev.ctrlKey || ev.metaKey || ev.altKey) return;
    const v = viewers.find(x => x.hover) || viewers.find(x => x.root.contains(document.activeElement));
    const own = ev.target.type === "range" || ev.target.tagName === "SELECT";
    if (!v || (own && ev.key.startsWith("Arrow"))) return;   // the sliders' and lists' own keys
    if (v.key(ev.key)) ev.preventDefault();
  });

  function start() {
    document.querySelectorAll(".viewer").forEach(root => viewers.push(new Viewer(root)));
    document.documentElement.dataset.viewers = String(viewers.length);   // for tests: all built
  }
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
  else start();
})();
