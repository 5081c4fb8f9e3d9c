// The cell page: every node's state, validity, health flags, method, rate and counters.
"use strict";

start((info) => {
  const body = document.querySelector("#nodes tbody");
  const rows = info.nodes.map((n, i) => {
    const tr = el("tr", { id: `node-${i}` });
    tr.append(el("td", {}, el("a", { href: `/node/${i}`, text: n.name })));
    for (let k = 0; k < 11; k++) tr.append(el("td", k >= 3 ? { class: "num" } : {}));
    body.append(tr);
    return tr;
  });
  Console.handlers.push((msg) => {
    for (const n of msg.nodes || []) {
      const s = n.snap, cells = rows[n.i].children;
      const st = el("span", { class: `state ${stateClass(s)}${s && !s.valid ? " invalid" : ""}`, text: stateText(s) });
      cells[1].replaceChildren(st);
      cells[2].replaceChildren(flagsElement(s));
      cells[3].textContent = s ? s.method : info.nodes[n.i].method;
      cells[4].textContent = fmt(n.rate_hz, 0);
      if (!s) continue;
      cells[5].textContent = fmt(s.f_sum_n);
      cells[6].textContent = s.scans;
      cells[7].textContent = s.lost_scans;
      cells[8].textContent = s.bus_errors;
      cells[9].textContent = s.slip_events;
      cells[10].textContent = s.state_changes;
      cells[11].textContent = s.frame_age_s === null ? "-" : fmt(s.frame_age_s * 1000, 0);
    }
  });
});
