/* mitsuba_lab sweep report: the comparison viewer (see viewer.py for the data it reads).
 *
 * Every .viewer element carries its data as JSON: renders as base64 little-endian half floats
 * (linear RGB), the error and variance maps as half-float log10 values. All drawing happens
 * here: exposure and the sRGB curve for images, a colour map for the maps, and one view
 * (zoom, pan) shared by every image of a viewer. Keys act on the viewer under the mouse or
 * holding the focus, so the page still scrolls with the arrow keys elsewhere.
 */
(function () {
  "use strict";
  const MAX_SIDE = 512;       // the image area's longer side in CSS pixels
  const CROP_BOX = [112, 64]; // a crop is enlarged to fit this box
  const MODES = { e: "err", v: "var" };
  const MODE_NAMES = { err: "log10 relative error |x - ref| / sqrt(ref^2 + 0.01)",
                       var: "log10 per-pixel variance across seeds / (ref^2 + 0.01)" };

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
      this.luts = { err: colourTable(d.colormaps.err), var: colourTable(d.colormaps.var) };
      const fit = Math.min(MAX_SIDE / d.width, MAX_SIDE / d.height);
      this.fit = fit >= 1 ? Math.floor(fit) : fit;        // whole screen pixels per image pixel
      this.build();
      this.resetView();
      this.selectSet(this.set);
    }

    pixels(key) {
      return this.decoded[key] || (this.decoded[key] = decodeHalf(this.data.images[key]));
    }

    entries() { return this.data.sets[this.set].entries; }

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
      this.legend = el("span", { className: "vw-legend" });
      this.legend.style.display = "none";
      this.legendText = el("span", { className: "vw-help" });
      this.status = el("div", { className: "vw-status" });
      this.readout = el("div", { className: "vw-status" });
      root.append(this.setRow, this.labelRow,
        el("div", { className: "vw-body" }, this.canvas, this.crops),
        el("div", { className: "vw-row" }, "exposure ", this.slider, this.expText,
           toggle("err", "relative error (e)"), toggle("var", "variance (v)"),
           el("label", {}, regions, " regions (r)"),
           el("button", { textContent: "reset view (0)", onclick: () => { this.resetView(); this.draw(); } }),
           this.legend, this.legendText),
        this.status, this.readout,
        el("div", { className: "vw-help", textContent: "keys (mouse over the viewer): 1-9 or \u2190 \u2192 " +
          "image, \u2191 \u2193 comparison, e error map, v variance, r regions, + - exposure, 0 reset view; " +
          "wheel zooms, drag pans, double-click resets" }));
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
      c.addEventListener("mousedown", ev => { this.drag = [ev.clientX, ev.clientY]; c.style.cursor = "grabbing"; });
      window.addEventListener("mouseup", () => { this.drag = null; c.style.cursor = ""; });
      window.addEventListener("mousemove", ev => {
        if (!this.drag) return;
        this.view.x += ev.clientX - this.drag[0];
        this.view.y += ev.clientY - this.drag[1];
        this.drag = [ev.clientX, ev.clientY];
        this.draw();
      });
      c.addEventListener("mousemove", ev => { this.pointer = ev; this.showPixel(); });
      c.addEventListener("dblclick", () => { this.resetView(); this.draw(); });
    }

    // -- state changes ----------------------------------------------------------------
    selectSet(i) {
      const n = this.data.sets.length, key = this.entries()[this.entry]?.key;
      this.set = ((i % n) + n) % n;
      const same = this.entries().findIndex(e => e.key === key);   // keep the strategy shown (its label may carry a mark)
      this.entry = same >= 0 ? same : Math.min(this.entry, this.entries().length - 1);
      [...this.setRow.querySelectorAll("button")].forEach((b, k) => b.classList.toggle("vw-on", k === this.set));
      this.labelRow.replaceChildren(...this.entries().map((e, k) => el("button", {
        textContent: `${k + 1} ${e.label}`, title: e.detail, onclick: () => this.select(k) })));
      this.buildCrops();
      this.select(this.entry);
    }

    select(k) {
      const n = this.entries().length;
      this.entry = ((k % n) + n) % n;
      [...this.labelRow.children].forEach((b, j) => b.classList.toggle("vw-on", j === this.entry));
      this.status.textContent = `${this.data.sets[this.set].name} \u2014 ${this.entries()[this.entry].detail}`;
      this.update();
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
        this.legendText.textContent = `${lo} \u2026 ${hi}: ${MODE_NAMES[mode]}`;
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
        this.select(this.entry + (k === "ArrowRight" ? 1 : -1));
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
      const src = this.pixels(image ? entry.rgb : entry[this.mode]), k = 2 ** (this.exposure + offset);
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
      this.draw();
      this.drawCrops();
    }

    draw() {
      const ctx = this.canvas.getContext("2d"), v = this.view;
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.fillStyle = "#222";
      ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
      ctx.imageSmoothingEnabled = false;
      ctx.setTransform(v.s, 0, 0, v.s, v.x, v.y);
      ctx.drawImage(this.off, 0, 0);
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      this.showPixel();
      if (!this.showRegions) return;
      ctx.strokeStyle = "cyan";
      ctx.fillStyle = "cyan";
      ctx.font = "11px sans-serif";
      for (const [name, [x0, y0, x1, y1]] of Object.entries(this.data.regions)) {
        ctx.strokeRect(v.x + x0 * v.s - 0.5, v.y + y0 * v.s - 0.5, (x1 - x0) * v.s + 1, (y1 - y0) * v.s + 1);
        ctx.fillText(name, v.x + x0 * v.s, v.y + y0 * v.s - 3);
      }
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
      }
    }

    showPixel() {
      const ev = this.pointer;
      if (!ev) return;
      const r = this.canvas.getBoundingClientRect(), v = this.view, d = this.data;
      const x = Math.floor((ev.clientX - r.left - v.x) / v.s), y = Math.floor((ev.clientY - r.top - v.y) / v.s);
      if (x < 0 || y < 0 || x >= d.width || y >= d.height) { this.readout.textContent = ""; return; }
      const e = this.entries()[this.entry], i = y * d.width + x, rgb = this.pixels(e.rgb);
      const f = n => n.toPrecision(3);
      this.readout.textContent =
        `pixel (${x}, ${y}): RGB ${f(rgb[3 * i])} ${f(rgb[3 * i + 1])} ${f(rgb[3 * i + 2])}, ` +
        `relative error 10^${this.pixels(e.err)[i].toFixed(2)}, variance 10^${this.pixels(e.var)[i].toFixed(2)}`;
    }
  }

  const viewers = [];
  document.addEventListener("keydown", ev => {
    if (ev.ctrlKey || ev.metaKey || ev.altKey) return;
    const v = viewers.find(x => x.hover) || viewers.find(x => x.root.contains(document.activeElement));
    if (!v || (ev.target.type === "range" && ev.key.startsWith("Arrow"))) return;   // the slider's own keys
    if (v.key(ev.key)) ev.preventDefault();
  });

  function start() {
    document.querySelectorAll(".viewer").forEach(root => viewers.push(new Viewer(root)));
    document.documentElement.dataset.viewers = String(viewers.length);   // for tests: all built
  }
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
  else start();
})();
