// surge watch: draws the frames the server sends over /ws on the street map of /api/map. No dependencies.
"use strict";

const STATE_COLOURS = ["#2b8a3e", "#1c7ed6", "#7048e8", "#f08c00"];
const STATE_NAMES = ["free", "to pickup", "occupied", "deciding"];
const PAD = 24;
const canvas = document.getElementById("map");
const ctx = canvas.getContext("2d");
let city = null, px = null, streets = null, heat = null, heatKey = "", frame = null, playing = false, socket = null;

function $(id) { return document.getElementById(id); }

function project(m) {
  // unit-square coordinates (north up) to canvas pixels; a long north-south city is turned a quarter clockwise (north to the right)
  const n = m.xy.length / 2, longest = 1400, tallest = 900;
  let maxX = 1e-9, maxY = 1e-9;
  for (let i = 0; i < n; i++) { maxX = Math.max(maxX, m.xy[2 * i]); maxY = Math.max(maxY, m.xy[2 * i + 1]); }
  const turned = maxY > 1.5 * maxX, w = turned ? maxY : maxX, h = turned ? maxX : maxY;
  let scale = (longest - 2 * PAD) / w;
  if (h * scale + 2 * PAD > tallest) scale = (tallest - 2 * PAD) / h;
  canvas.width = Math.round(w * scale + 2 * PAD);
  canvas.height = Math.round(h * scale + 2 * PAD);
  $("north").textContent = turned ? "north is to the right" : "north is up";
  const out = new Float64Array(2 * n);
  for (let i = 0; i < n; i++) {
    const x = m.xy[2 * i], y = m.xy[2 * i + 1];
    out[2 * i] = turned ? PAD + y * scale : PAD + x * scale;
    out[2 * i + 1] = turned ? PAD + x * scale : canvas.height - PAD - y * scale;
  }
  return out;
}

function layer() { const c = document.createElement("canvas"); c.width = canvas.width; c.height = canvas.height; return c; }

function drawStreets() {
  streets = layer();
  const g = streets.getContext("2d");
  g.strokeStyle = "rgba(73, 80, 87, 0.45)";
  g.lineWidth = 1;
  g.beginPath();
  const s = city.streets;
  for (let k = 0; k < s.length; k += 2) {
    g.moveTo(px[2 * s[k]], px[2 * s[k] + 1]);
    g.lineTo(px[2 * s[k + 1]], px[2 * s[k + 1] + 1]);
  }
  g.stroke();
}

function heatColour(x) {
  // 0 -> pale yellow, 1 -> deep red
  const t = Math.max(0, Math.min(1, x));
  const r = 255, gr = Math.round(237 - 200 * t), b = Math.round(160 - 140 * t);
  return `rgb(${r},${gr},${b})`;
}

function drawHeat(values, vmax) {
  heat = layer();
  if (!values) return;
  const g = heat.getContext("2d"), n = city.node_sector.length;
  const radius = Math.max(4, 0.9 * Math.sqrt((canvas.width - 2 * PAD) * (canvas.height - 2 * PAD) / n));
  g.globalAlpha = 0.55;
  for (let i = 0; i < n; i++) {
    const v = values[city.node_sector[i]];
    if (v === null || v === undefined) continue;
    g.fillStyle = heatColour(v / vmax);
    g.beginPath();
    g.arc(px[2 * i], px[2 * i + 1], radius, 0, 2 * Math.PI);
    g.fill();
  }
}

function drawScale(vmax) {
  const c = $("scale"), g = c.getContext("2d");
  for (let x = 0; x < c.width; x++) { g.fillStyle = heatColour(x / c.width); g.fillRect(x, 0, 1, c.height); }
  $("scale-max").textContent = vmax > 0 ? vmax.toFixed(2) : "–";
}

function star(g, x, y, r) {
  g.beginPath();
  for (let k = 0; k < 10; k++) {
    const a = Math.PI / 2 + k * Math.PI / 5, rr = k % 2 ? r * 0.45 : r;
    g.lineTo(x + rr * Math.cos(a), y - rr * Math.sin(a));
  }
  g.closePath();
  g.fill();
  g.stroke();
}

function currentEvents(f) {
  if (!city.events || !city.events.length) return [];
  return city.events[Math.min(f.hour || 0, city.events.length - 1)] || [];
}

function draw() {
  if (!city || !frame || frame.pos === undefined) return;
  const which = document.querySelector("input[name=layer]:checked").value;
  const values = which === "none" ? null : frame[which];
  const both = [].concat(frame.forecast || [], frame.realised || []).filter(v => v !== null);
  const vmax = Math.max(0.01, ...both);
  const key = which + JSON.stringify(values) + vmax;
  if (key !== heatKey) { drawHeat(values, vmax); drawScale(vmax); heatKey = key; }
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  ctx.drawImage(heat, 0, 0);
  ctx.drawImage(streets, 0, 0);
  const r = frame.requests;
  for (let k = 0; k < r.length; k += 2) {
    const age = Math.min(1, r[k + 1] / 15);
    ctx.fillStyle = `rgb(${Math.round(255 - 31 * age)},${Math.round(224 - 175 * age)},${Math.round(102 - 53 * age)})`;
    ctx.strokeStyle = "rgba(0,0,0,0.6)";
    ctx.fillRect(px[2 * r[k]] - 3.5, px[2 * r[k] + 1] - 3.5, 7, 7);
    ctx.strokeRect(px[2 * r[k]] - 3.5, px[2 * r[k] + 1] - 3.5, 7, 7);
  }
  ctx.fillStyle = "#c2255c";
  ctx.strokeStyle = "#fff";
  ctx.lineWidth = 1;
  for (const ev of currentEvents(frame)) star(ctx, px[2 * ev.node], px[2 * ev.node + 1], 7);
  for (let a = 0; a < frame.pos.length; a++) {
    const node = frame.pos[a];
    ctx.fillStyle = STATE_COLOURS[frame.state[a]];
    ctx.strokeStyle = "#fff";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.arc(px[2 * node], px[2 * node + 1], 5.5, 0, 2 * Math.PI);
    ctx.fill();
    ctx.stroke();
  }
}

function panel(msg) {
  const f = msg.frame;
  $("minute").textContent = f.minute;
  $("minutes").textContent = f.minutes;
  $("taxis").textContent = f.taxis;
  if (f.pos === undefined) { $("status").textContent = "waiting for " + f.waiting_for; return; }
  $("cost").textContent = f.cost;
  $("served").textContent = f.served;
  $("waiting").textContent = f.waiting;
  $("fallbacks").textContent = f.fallbacks;
  $("waves").textContent = f.waves;
  const counts = [0, 0, 0, 0];
  for (const s of f.state) counts[s]++;
  let status = STATE_NAMES.map((name, i) => `${counts[i]} ${name}`).join(", ");
  status += f.cost_to ? `; cost and served count minutes ${(f.since || 0) + 1}–${f.cost_to}` : "";
  if (f.since) status += ` (this view joined at minute ${f.since + 1})`;
  if (f.done) status += f.stop === "done" ? "; the run is over" : `; the run stopped: ${f.stop}`;
  $("status").textContent = status;
  const events = currentEvents(f);
  const shown = events.slice(0, 8).map(ev => `${ev.title} (${ev.start}–${ev.end})`);
  if (events.length > shown.length) shown.push(`and ${events.length - shown.length} more`);
  $("events").replaceChildren(...(shown.length ? shown : ["none"]).map(text => {
    const li = document.createElement("li");
    li.textContent = text;
    return li;
  }));
  if (city.mode === "replay") {
    $("seek").max = msg.count - 1;
    $("seek").value = msg.index;
    $("play").textContent = msg.playing ? "pause" : "play";
  }
  playing = msg.playing;
  document.body.dataset.frameIndex = msg.index;
  document.body.dataset.done = f.done ? "1" : "0";
}

function send(command) { if (socket && socket.readyState === WebSocket.OPEN) socket.send(command); }

function connect() {
  socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  socket.onmessage = (e) => {
    const msg = JSON.parse(e.data);
    frame = msg.frame;
    panel(msg);
    draw();
  };
  socket.onclose = () => { $("status").textContent += " (disconnected from surge watch)"; };
}

async function start() {
  let res;
  for (;;) {
    res = await fetch("/api/map");
    if (res.ok) break;
    $("status").textContent = "waiting for the run's city";
    await new Promise(r => setTimeout(r, 500));
  }
  city = await res.json();
  $("mode").textContent = city.mode;
  const run = city.run || {};
  $("title").textContent = `${run.run ? "run " + run.run + ", " : ""}${run.policy || ""} on ${run.scenario || city.name}, ` +
    `${city.date} ${city.hour}:00, ${run.taxis} taxis, ${run.minutes} min`;
  px = project(city);
  drawStreets();
  if (city.mode === "replay") {
    $("player").hidden = false;
    $("play").onclick = () => send(playing ? "pause" : "play");
    $("step").onclick = () => send("step");
    $("back").onclick = () => send("back");
    $("seek").oninput = () => send("seek " + $("seek").value);
    $("speed").onchange = () => send("speed " + $("speed").value);
  }
  for (const input of document.querySelectorAll("input[name=layer]")) input.onchange = () => { heatKey = ""; draw(); };
  connect();
}

start();
