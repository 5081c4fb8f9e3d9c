// The node page: the live heat map (newtons, colour scale, centre of force and trail), the
// deciding method's scores and the paper's indicators over 30 s, the state lane, the health
// flags, the commands and the PLC's register block.
"use strict";

const index = Number(location.pathname.split("/").pop());
Console.watch = index;
Console.seen.frames = 0;

start((info) => {
  const node = info.nodes[index];
  document.getElementById("title").textContent = `node ${node.name}`;
  document.title = `eskin-bus: ${node.name}`;
  const heat = new HeatMap(document.getElementById("heatmap"), document.getElementById("scale"), node);
  window.heatCell = (r, c) => heat.cell(r, c);
  const [slipA, slipB] = node.slip, [varA, varB] = node.variable;
  const scores = new Trend(document.getElementById("scores"), node.score_names, ["#ff8a65", "#4dd0e1"], [
    [slipA, "#ff8a65", `slip ${node.score_names[0]}`], [slipB, "#4dd0e1", `slip ${node.score_names[1]}`],
    [varA, "#ffd54f", "varying"], [varB, "#ffd54f", "varying"]]);
  const indicators = new Trend(document.getElementById("indicators"), ["R_coe", "R_dw"], ["#ff8a65", "#4dd0e1"], []);
  const lane = new Lane(document.getElementById("lane"));
  const changes = document.querySelector("#changes tbody");
  let snap = null, lastT = null;

  const buttons = document.querySelectorAll("#commands button");
  const s = Console.session;
  const mayCommand = s && s.commands && s.role === "operator";
  for (const b of buttons) {
    b.disabled = !mayCommand;
    b.title = mayCommand ? "" : (s && s.commands ? "log in as an operator to command" : "read-only console");
    b.onclick = () => command(index, b.dataset.command);
  }

  Console.handlers.push((msg) => {
    for (const n of msg.nodes || []) {
      if (n.i !== index) continue;
      snap = n.snap;
      const st = document.getElementById("state");
      st.className = `state ${stateClass(snap)}${snap && !snap.valid ? " invalid" : ""}`;
      st.textContent = stateText(snap);
      document.getElementById("flags").replaceChildren(flagsElement(snap));
      if (snap) {
        document.getElementById("numbers").textContent =
          `F ${fmt(snap.f_sum_n)} N  CoF ${fmt(snap.xc_mm, 1)}, ${fmt(snap.yc_mm, 1)} mm  ` +
          `${snap.score_names[0]} ${fmt(snap.score_a)}  ${snap.score_names[1]} ${fmt(snap.score_b)}  ` +
          `method ${snap.method}  rate ${fmt(n.rate_hz, 0)} scans/s  scans ${snap.scans}  lost ${snap.lost_scans}  ` +
          `bus errors ${snap.bus_errors}  slips ${snap.slip_events}  changes ${snap.state_changes}`;
      }
    }
    if (msg.frame && msg.frame.node === index) {
      lastT = msg.frame.t;
      heat.draw(msg.frame.forces, msg.frame.t, snap);
      Console.seen.frames += 1;
      Console.seen.lastFrame = msg.received;
      Console.seen.lastFrameT = msg.frame.t;
    }
    if (msg.trend && msg.trend.node === index) {
      for (const [, t, rcoe, rdw, a, b] of msg.trend.points) { scores.add(t, a, b); indicators.add(t, rcoe, rdw); }
      scores.draw(); indicators.draw();
    }
    for (const c of msg.lane || []) {
      if (c.node !== index) continue;
      lane.add(c);
      const tr = el("tr", { class: `change ${c.state}` }, el("td", { class: "num", text: c.t.toFixed(2) }),
        el("td", {}, el("span", { class: `state ${c.state}${c.valid ? "" : " invalid"}`, text: c.state })),
        el("td", { text: c.valid ? "valid" : "not valid" }), el("td", { text: new Date(c.wall * 1000).toLocaleTimeString() }));
      changes.prepend(tr);
      while (changes.children.length > 20) changes.lastChild.remove();
      if (c.state === "slip") {  // drawn now: when it appeared, by this page's clock
        lane.draw(Math.max(lastT || c.t, c.t));
        (Console.seen.laneSlips = Console.seen.laneSlips || []).push({ page: nowMs(), decided: c.wall * 1000, t: c.t });
      }
    }
    if (lastT !== null || (msg.lane && msg.lane.length)) lane.draw(lastT);
    if (msg.registers && msg.registers.node === index) {
      const r = msg.registers;
      document.getElementById("registers-title").textContent = r.source === "written"
        ? `PLC registers, as the bridge last wrote them to the PLC (${r.acknowledged ? "acknowledged" : "not acknowledged"})`
        : "PLC registers, as the PLC reads them";
      document.getElementById("registers-panel").dataset.source = r.source;
      document.getElementById("registers-panel").dataset.acknowledged = String(r.acknowledged);
      const t = el("table", { id: "register-table" });
      t.append(el("tr", {}, el("th", { text: "STATUS bits" }), el("td", { id: "status-bits", text: msg.registers.bits.join(" ") || "-" })));
      for (const [k, v] of Object.entries(msg.registers.values)) {
        t.append(el("tr", {}, el("th", { text: k }), el("td", { class: "num", "data-register": k,
          text: k === "STATUS" || k === "FLAGS" ? `0x${v.toString(16).padStart(4, "0")}` : String(v) })));
      }
      document.getElementById("registers").replaceChildren(t);
    }
  });
});
