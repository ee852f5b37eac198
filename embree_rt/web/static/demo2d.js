// The 2D demo: keeps the layout, sends it to the server on every change and draws the light
// paths it gets back. No physics here: the server traces the rays.
"use strict";

const canvas = document.getElementById("demo");
const context = canvas.getContext("2d");
const WIDTH = 960;
const HEIGHT = 600;
const LIGHT_GRAB = 14;
const LEVELS = 16; // shades of light a segment is drawn with
const status = document.getElementById("status");

const state = {
  circles: [
    { x: 420, y: 300, r: 90, material: "glass" },
    { x: 700, y: 170, r: 60, material: "mirror" },
    { x: 690, y: 450, r: 55, material: "matte" },
  ],
  light: [150, 330],
  material: "glass",
};
let paths = null; // the server's answer: points, weights, kinds packed path after path
let inFlight = false;
let stale = false;
let sentAt = 0;
let nextId = 0;

const sliders = {};
for (const name of ["radius", "rays", "spread", "aim"]) {
  const input = document.getElementById(name);
  const output = document.getElementById(`${name}-value`);
  const show = () => {
    output.textContent = name === "spread" || name === "aim" ? `${input.value}°` : input.value;
  };
  show();
  input.addEventListener("input", () => {
    show();
    if (name !== "radius") changed();
  });
  sliders[name] = input;
}

function setupCanvas() {
  const ratio = window.devicePixelRatio || 1;
  canvas.width = Math.round(WIDTH * ratio);
  canvas.height = Math.round(HEIGHT * ratio);
  canvas.style.width = `${WIDTH}px`;
  context.setTransform(ratio, 0, 0, ratio, 0, 0);
}

const connection = openSocket("/ws/2d", onMessage, (text, isError) =>
  setStatus(status, text, isError)
);
connection.ready.then(changed);

function changed() {
  if (inFlight) {
    stale = true;
    return;
  }
  inFlight = true;
  stale = false;
  sentAt = performance.now();
  connection.send({
    type: "trace",
    id: nextId++,
    circles: state.circles,
    light: state.light,
    rays: Number(sliders.rays.value),
    spread: Number(sliders.spread.value),
    aim: Number(sliders.aim.value),
  });
}

function onMessage(message) {
  if (message.type === "error") {
    setStatus(status, message.message, true);
  } else if (message.type === "rays") {
    paths = message;
    const segments = message.weights.length;
    const roundTrip = performance.now() - sentAt;
    setStatus(
      status,
      `${segments} segments · traced in ${message.trace_ms.toFixed(1)} ms · ` +
        `answered in ${roundTrip.toFixed(1)} ms`
    );
    canvas.dataset.answered = String(message.id);
  }
  inFlight = false;
  if (stale) changed();
  else draw();
}

function draw() {
  context.clearRect(0, 0, WIDTH, HEIGHT);
  const sky = context.createRadialGradient(
    state.light[0], state.light[1], 0, state.light[0], state.light[1], 700
  );
  sky.addColorStop(0, "#1a1d29");
  sky.addColorStop(1, "#07090e");
  context.fillStyle = sky;
  context.fillRect(0, 0, WIDTH, HEIGHT);
  drawRays();
  for (const circle of state.circles) drawCircle(circle);
  drawLight();
}

function drawRays() {
  context.save();
  context.globalCompositeOperation = "lighter";
  context.lineWidth = 1.3;
  context.lineCap = "round";
  // By SEGMENT_KINDS: from the light, reflected, refracted, totally internally reflected.
  const colors = ["255, 214, 120", "255, 236, 180", "130, 210, 255", "190, 160, 255"];
  if (paths === null) return;
  const { points, weights, kinds, starts } = paths;
  // One stroke per kind and level of light: a thousand separate strokes take the browser
  // tens of milliseconds to paint, a few dozen paths almost nothing.
  const buckets = new Map();
  for (let path = 0; path + 1 < starts.length; path++) {
    // Path k's points are starts[k] .. starts[k + 1] - 1; its segments' weights start k
    // places earlier (each path has one point more than it has segments).
    for (let point = starts[path]; point + 1 < starts[path + 1]; point++) {
      const segment = point - path;
      const key = kinds[segment] * LEVELS + Math.round(weights[segment] * (LEVELS - 1));
      if (!buckets.has(key)) buckets.set(key, []);
      buckets.get(key).push(point);
    }
  }
  for (const [key, segmentPoints] of buckets) {
    const level = (key % LEVELS) / (LEVELS - 1);
    context.strokeStyle = `rgba(${colors[Math.floor(key / LEVELS)]}, ${0.15 + 0.7 * level})`;
    context.beginPath();
    for (const point of segmentPoints) {
      context.moveTo(points[2 * point], points[2 * point + 1]);
      context.lineTo(points[2 * point + 2], points[2 * point + 3]);
    }
    context.stroke();
  }
  context.restore();
}

function drawCircle(circle) {
  context.save();
  context.beginPath();
  context.arc(circle.x, circle.y, circle.r, 0, 2 * Math.PI);
  if (circle.material === "glass") {
    context.fillStyle = "rgba(120, 200, 255, 0.10)";
    context.strokeStyle = "rgba(160, 220, 255, 0.85)";
  } else if (circle.material === "mirror") {
    const shine = context.createLinearGradient(
      circle.x - circle.r, circle.y - circle.r, circle.x + circle.r, circle.y + circle.r
    );
    shine.addColorStop(0, "rgba(245, 248, 255, 0.75)");
    shine.addColorStop(0.5, "rgba(150, 160, 180, 0.45)");
    shine.addColorStop(1, "rgba(60, 66, 80, 0.6)");
    context.fillStyle = shine;
    context.strokeStyle = "rgba(245, 248, 255, 1)";
    context.lineWidth = 3;
  } else {
    context.fillStyle = "rgba(52, 48, 46, 0.97)";
    context.strokeStyle = "rgba(105, 98, 92, 0.9)";
  }
  if (circle.material !== "mirror") context.lineWidth = 2;
  context.fill();
  context.stroke();
  context.restore();
}

function drawLight() {
  const [x, y] = state.light;
  context.save();
  const glow = context.createRadialGradient(x, y, 0, x, y, 26);
  glow.addColorStop(0, "rgba(255, 235, 170, 0.9)");
  glow.addColorStop(1, "rgba(255, 200, 90, 0)");
  context.fillStyle = glow;
  context.beginPath();
  context.arc(x, y, 26, 0, 2 * Math.PI);
  context.fill();
  context.fillStyle = "#fff6d8";
  context.beginPath();
  context.arc(x, y, 6, 0, 2 * Math.PI);
  context.fill();
  context.restore();
}

// -- editing ---------------------------------------------------------------------------------

function toScene(event) {
  const box = canvas.getBoundingClientRect();
  return [
    ((event.clientX - box.left) * WIDTH) / box.width,
    ((event.clientY - box.top) * HEIGHT) / box.height,
  ];
}

function circleAt([x, y]) {
  for (let k = state.circles.length - 1; k >= 0; k--) {
    const c = state.circles[k];
    if (Math.hypot(x - c.x, y - c.y) <= c.r) return k;
  }
  return -1;
}

let drag = null;
canvas.addEventListener("pointerdown", (event) => {
  if (event.button !== 0) return;
  const point = toScene(event);
  const onLight = Math.hypot(point[0] - state.light[0], point[1] - state.light[1]) <= LIGHT_GRAB;
  const index = onLight ? -1 : circleAt(point);
  drag = { start: point, moved: false, light: onLight, index };
  canvas.setPointerCapture(event.pointerId);
});
canvas.addEventListener("pointermove", (event) => {
  if (drag === null) return;
  const point = toScene(event);
  if (!drag.moved && Math.hypot(point[0] - drag.start[0], point[1] - drag.start[1]) < 3) return;
  drag.moved = true;
  const x = Math.min(Math.max(point[0], 0), WIDTH);
  const y = Math.min(Math.max(point[1], 0), HEIGHT);
  if (drag.light) {
    state.light = [x, y];
  } else if (drag.index >= 0) {
    state.circles[drag.index].x = x;
    state.circles[drag.index].y = y;
  } else {
    return;
  }
  changed();
});
canvas.addEventListener("pointerup", (event) => {
  if (drag === null) return;
  const { moved, light, index } = drag;
  drag = null;
  if (moved || light || index >= 0) return;
  const [x, y] = toScene(event);
  if (state.circles.length >= 64) {
    setStatus(status, "at most 64 circles", true);
    return;
  }
  state.circles.push({ x, y, r: Number(sliders.radius.value), material: state.material });
  changed();
});
function removeAt(event) {
  event.preventDefault();
  const index = circleAt(toScene(event));
  if (index >= 0) {
    state.circles.splice(index, 1);
    changed();
  }
}
canvas.addEventListener("dblclick", removeAt);
canvas.addEventListener("contextmenu", removeAt);

document.getElementById("materials").addEventListener("click", (event) => {
  const button = event.target.closest("button");
  if (!button) return;
  state.material = button.dataset.material;
  for (const other of document.querySelectorAll("#materials button")) {
    other.classList.toggle("selected", other === button);
  }
});
document.getElementById("clear").addEventListener("click", () => {
  state.circles = [];
  changed();
});

setupCanvas();
draw();
