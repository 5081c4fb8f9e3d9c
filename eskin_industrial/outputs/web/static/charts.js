// Canvas drawing: the heat map with its colour scale, time series over a window, the state lane.
"use strict";

const STATE_COLOURS = { slip: "#e53935", variable_force: "#ffb300", stable: "#43a047", no_contact: "#1e88e5",
                        unknown: "#757575" };

// black -> red -> yellow -> white over [0, 1]
function heatColour(v) {
  const x = Math.max(0, Math.min(1, v));
  const c = (y) => Math.round(255 * Math.max(0, Math.min(1, y)));
  return [c(3 * x), c(3 * x - 1), c(3 * x - 2)];
}

class HeatMap {
  constructor(canvas, scale, node) {
    this.canvas = canvas; this.scale = scale; this.node = node;
    this.trail = [];          // [t, x_mm, y_mm] of the last TRAIL_S
    this.max = 0.5;
    const xs = node.x_mm, ys = node.y_mm;
    this.x0 = Math.min(...xs); this.x1 = Math.max(...xs);
    this.y0 = Math.min(...ys); this.y1 = Math.max(...ys);
  }
  cell(r, c) {  // the pixel centre of a taxel (tests read it back with getImageData)
    const w = this.canvas.width / this.node.cols, h = this.canvas.height / this.node.rows;
    return [Math.floor(c * w + w / 2), Math.floor(r * h + h / 2)];
  }
  toPixel(x, y) {  // a centre of force in mm onto the taxels' centres
    const n = this.node, w = this.canvas.width / n.cols, h = this.canvas.height / n.rows;
    const px = this.x1 > this.x0 ? w / 2 + (x - this.x0) / (this.x1 - this.x0) * (this.canvas.width - w)
                                 : this.canvas.width / 2;
    const py = this.y1 > this.y0 ? h / 2 + (y - this.y0) / (this.y1 - this.y0) * (this.canvas.height - h)
                                 : this.canvas.height / 2;
    return [px, py];
  }
  draw(forces, t, snap) {
    const n = this.node, ctx = this.canvas.getContext("2d");
    const w = this.canvas.width / n.cols, h = this.canvas.height / n.rows;
    let top = 0;
    for (const f of forces) if (f !== null && f > top) top = f;
    this.max = Math.max(0.5, top);  // at least 0.5 N: sensor noise stays dark
    ctx.font = "11px sans-serif";
    ctx.textAlign = "center"; ctx.textBaseline = "middle";
    for (let r = 0; r < n.rows; r++) {
      for (let c = 0; c < n.cols; c++) {
        const f = forces[r * n.cols + c];
        const [R, G, B] = f === null ? [60, 0, 60] : heatColour(f / this.max);
        ctx.fillStyle = `rgb(${R},${G},${B})`;
        ctx.fillRect(c * w, r * h, w, h);
        ctx.strokeStyle = "#222"; ctx.strokeRect(c * w, r * h, w, h);
        ctx.fillStyle = R + G + B > 400 ? "#000" : "#ccc";
        ctx.fillText(f === null ? "nan" : f.toFixed(2), c * w + w / 2, r * h + h - 8);
      }
    }
    if (snap && snap.xc_mm !== null && snap.contact !== false && snap.f_sum_n > 0.05) {
      this.trail.push([t, snap.xc_mm, snap.yc_mm]);
    }
    while (this.trail.length && t - this.trail[0][0] > 2.0) this.trail.shift();
    if (this.trail.length) {
      ctx.strokeStyle = "#00e5ff"; ctx.lineWidth = 2; ctx.beginPath();
      this.trail.forEach(([, x, y], k) => { const [px, py] = this.toPixel(x, y); k ? ctx.lineTo(px, py) : ctx.moveTo(px, py); });
      ctx.stroke();
      const [, x, y] = this.trail[this.trail.length - 1];
      const [px, py] = this.toPixel(x, y);
      ctx.beginPath(); ctx.arc(px, py, 5, 0, 2 * Math.PI); ctx.stroke();
      ctx.lineWidth = 1;
    }
    this.drawScale();
  }
  drawScale() {
    const ctx = this.scale.getContext("2d"), W = this.scale.width;
    ctx.clearRect(0, 0, W, this.scale.height);
    for (let x = 0; x < W - 80; x++) {
      const [R, G, B] = heatColour(x / (W - 80));
      ctx.fillStyle = `rgb(${R},${G},${B})`; ctx.fillRect(40 + x, 4, 1, 14);
    }
    ctx.fillStyle = "#ccc"; ctx.font = "11px sans-serif"; ctx.textBaseline = "top";
    ctx.textAlign = "left"; ctx.fillText("0 N", 4, 6);
    ctx.textAlign = "right"; ctx.fillText(`${this.max.toFixed(2)} N`, W - 2, 6);
    ctx.textAlign = "center"; ctx.fillText(`${(this.max / 2).toFixed(2)}`, 40 + (W - 80) / 2, 20);
  }
}

// Two series over the last WINDOW_S of the sensor's clock, with threshold lines.
class Trend {
  constructor(canvas, names, colours, thresholds, windowS = 30) {
    this.canvas = canvas; this.names = names; this.colours = colours;
    this.thresholds = thresholds;  // [[value, colour, label], ...]
    this.windowS = windowS;
    this.points = [];  // [t, a, b]
  }
  add(t, a, b) {
    this.points.push([t, a, b]);
    while (this.points.length && t - this.points[0][0] > this.windowS) this.points.shift();
  }
  draw() {
    const ctx = this.canvas.getContext("2d"), W = this.canvas.width, H = this.canvas.height;
    ctx.fillStyle = "#000"; ctx.fillRect(0, 0, W, H);
    if (!this.points.length) return;
    const tEnd = this.points[this.points.length - 1][0], tStart = tEnd - this.windowS;
    let top = 0;
    for (const [, a, b] of this.points) top = Math.max(top, a || 0, b || 0);
    for (const [v] of this.thresholds) if (v !== null) top = Math.max(top, v * 1.5);
    top = top || 1;
    const X = (t) => (t - tStart) / this.windowS * W, Y = (v) => H - 4 - v / top * (H - 16);
    let shown = 0;
    for (const [v, colour, label] of this.thresholds) {
      if (v === null) continue;
      shown += 1;
      ctx.strokeStyle = colour; ctx.setLineDash([4, 3]); ctx.beginPath();
      ctx.moveTo(0, Y(v)); ctx.lineTo(W, Y(v)); ctx.stroke(); ctx.setLineDash([]);
      ctx.fillStyle = colour; ctx.font = "10px sans-serif"; ctx.textAlign = "right"; ctx.fillText(label, W - 2 - (shown - 1) * 90, Y(v) - 2);
    }
    for (let k = 0; k < 2; k++) {
      ctx.strokeStyle = this.colours[k]; ctx.beginPath();
      let first = true;
      for (const p of this.points) {
        const v = p[k + 1];
        if (v === null) { first = true; continue; }
        first ? ctx.moveTo(X(p[0]), Y(v)) : ctx.lineTo(X(p[0]), Y(v));
        first = false;
      }
      ctx.stroke();
      ctx.fillStyle = this.colours[k]; ctx.font = "11px sans-serif"; ctx.textAlign = "left";
      ctx.fillText(this.names[k], 4 + k * 110, 11);
    }
    ctx.fillStyle = "#888"; ctx.textAlign = "left"; ctx.fillText(`${top.toFixed(2)}`, 230, 11);
  }
}

// The state over the last WINDOW_S: coloured spans, with a mark at each change into slip or varying force.
class Lane {
  constructor(canvas, windowS = 30) { this.canvas = canvas; this.windowS = windowS; this.changes = []; this.tEnd = null; }
  add(change) { this.changes.push(change); if (this.changes.length > 512) this.changes.shift(); }
  draw(tEnd) {
    if (tEnd !== null && tEnd !== undefined) this.tEnd = tEnd;
    const ctx = this.canvas.getContext("2d"), W = this.canvas.width, H = this.canvas.height;
    ctx.fillStyle = "#000"; ctx.fillRect(0, 0, W, H);
    if (this.tEnd === null) return;
    const tStart = this.tEnd - this.windowS, X = (t) => (t - tStart) / this.windowS * W;
    for (let k = 0; k < this.changes.length; k++) {
      const c = this.changes[k], next = this.changes[k + 1];
      const a = Math.max(0, X(c.t)), b = Math.min(W, next ? X(next.t) : W);
      if (b <= 0 || a >= W) continue;
      ctx.fillStyle = STATE_COLOURS[c.state] || STATE_COLOURS.unknown;
      ctx.globalAlpha = c.valid ? 1 : 0.5;
      ctx.fillRect(a, 8, b - a, H - 16);
      ctx.globalAlpha = 1;
      if (c.state === "slip" || c.state === "variable_force") {
        ctx.fillStyle = "#fff"; ctx.fillRect(a, 0, 2, H);
      }
    }
  }
}
