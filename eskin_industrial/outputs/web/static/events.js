// The events page: each slip and varying-force episode, its time and detection delay (when the
// scene gives the truth), and a download of the raw scans around it (a recording CSV).
"use strict";

start((info) => {
  const body = document.querySelector("#episodes tbody");
  const rows = new Map();
  Console.handlers.push((msg) => {
    for (const e of msg.episodes || []) {
      const key = `${e.node}-${e.id}`;
      let tr = rows.get(key);
      if (!tr) {
        tr = el("tr", { id: `episode-${key}`, class: `episode ${e.state}` });
        for (let k = 0; k < 6; k++) tr.append(el("td", k === 2 || k === 4 ? { class: "num" } : {}));
        rows.set(key, tr);
        body.prepend(tr);
        if (e.state === "slip") {  // listed now: when it appeared, by this page's clock
          (Console.seen.eventSlips = Console.seen.eventSlips || []).push({ page: nowMs(), decided: e.wall * 1000, t: e.t });
        }
      }
      const c = tr.children;
      c[0].textContent = info.nodes[e.node].name;
      c[1].replaceChildren(el("span", { class: `state ${e.state}`, text: e.state }));
      c[2].textContent = e.t.toFixed(3);
      c[3].textContent = new Date(e.wall * 1000).toLocaleTimeString();
      c[4].textContent = e.delay_s === null ? "-" : (e.delay_s * 1000).toFixed(0);
      c[5].replaceChildren(e.capture
        ? el("a", { class: "capture", href: `/api/episodes/${e.node}/${e.id}.csv`, download: "", text: `CSV (${e.scans} scans)` })
        : el("span", { text: e.waiting ? "recording the window..." : "let go (the newest 16 are kept)" }));
    }
  });
});
