// The plant page: every Sparkplug B edge node and device on the broker, newest rows first
// drawn (each message holds all the rows: the page is redrawn, nothing is patched).
"use strict";

function clock(ms) {
  if (ms === null) return "-";
  const d = new Date(ms);
  return d.toLocaleTimeString([], { hour12: false }) + "." + String(ms % 1000).padStart(3, "0");
}

function rowId(r) { return ["row", r.group, r.edge, r.device === null ? "" : r.device].join("/"); }

function health(r) {
  const span = el("span");
  if (r.device === null) {
    span.append(el("span", { class: `flag${r.seq_gaps ? " on bad" : ""}`, "data-flag": "seq_gaps",
                             text: `seq gaps ${r.seq_gaps}` }));
  } else if (r.valid !== null) {
    span.append(el("span", { class: `flag on${r.valid ? "" : " bad"}`, "data-flag": "valid",
                             text: r.valid ? "valid" : "invalid" }));
  }
  return span;
}

function drawPlant(p) {
  const body = document.querySelector("#plant tbody");
  const edges = p.rows.filter((r) => r.device === null).length;
  document.getElementById("summary").textContent =
    `${edges} edge node${edges === 1 ? "" : "s"}, ${p.rows.length - edges} device${p.rows.length - edges === 1 ? "" : "s"}, ${p.messages} messages`;
  document.getElementById("empty").hidden = p.rows.length > 0;
  body.replaceChildren(...p.rows.map((r) => {
    const tr = el("tr", { id: rowId(r), class: `plant-${r.status}`, "data-status": r.status });
    const name = r.device === null ? `${r.group}/${r.edge}` : `\u00a0\u00a0${r.device}`;
    tr.append(el("td", { text: name }));
    tr.append(el("td", {}, el("span", { class: `status ${r.status}`, text: r.status })));
    if (r.device === null) {
      tr.append(el("td", { text: `bdSeq ${r.bd_seq === null ? "-" : r.bd_seq}` }), el("td", {}, health(r)));
      for (let k = 0; k < 5; k++) tr.append(el("td", k >= 2 ? { class: "num" } : {}));
    } else {
      const st = r.state || "unknown";
      tr.append(el("td", {}, el("span", { class: `state ${st}${r.valid === false ? " invalid" : ""}`, text: st })));
      tr.append(el("td", {}, health(r)), el("td", { text: r.method || "-" }), el("td", { text: clock(r.last_slip_ms) }));
      tr.append(el("td", { class: "num", text: r.slips === null ? "-" : r.slips }));
      tr.append(el("td", { class: "num", text: fmt(r.rate, 1) }));
      tr.append(el("td", { class: "num", text: r.frame_max === null ? "-" : `${fmt(r.frame_max)} / ${fmt(r.frame_sum, 1)}` }));
    }
    return tr;
  }));
  Console.seen.plantSeq = p.seq;
  Console.seen.plantRows = p.rows.length;
}

start(() => {
  Console.handlers.push((msg) => { if (msg.plant) drawPlant(msg.plant); });
});
