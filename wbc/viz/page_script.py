"""The trial page's script and style: a small canvas plotter and the one timeline that drives scene and plots.

Written here rather than taken from a plotting library so that a recorded page stays one file that works offline
and needs nothing beyond meshcat's own viewer script. The page reads ``wbcData`` (`wbc.viz.page.page_data`) and the
meshcat ``viewer``; it owns the time: every tick it seeks meshcat's animation to the page's time (the animation
itself never plays on its own), so the scene and the cursor on every plot move together by construction. It
exposes its state as ``window.wbcPage`` (``t``, ``cursorT``, ``sceneT``, ``playing``, ``speed``, ``follow``,
``plots: {key: {n, lines}}``, ``robots``, ``marks``) and mirrors it into ``<pre id="wbc-state">`` for tools that
read the DOM (a headless browser's ``--dump-dom``).

A live page (``wbcData.live``, `wbc.viz.live_page`) has no animation: it polls its server's ``/state`` for the
newest poses and the plots so far, its bar pushes the robot and sets the command, and once the trial has ended it
reloads into the recorded page.

URL hash: ``#t=3.2`` seeks there and pauses, ``&play`` plays on, ``&speed=0.25`` slow motion, ``&follow=0`` a fixed
camera. Keys: space play / pause, left / right one frame, ``[`` / ``]`` half / twice the speed.
"""

from __future__ import annotations

import json

from wbc.arena.plot_style import OKABE_ITO

__all__ = ["PAGE_SCRIPT", "PAGE_STYLE"]

PAGE_STYLE = """
html, body { margin: 0; height: 100%; font: 12px sans-serif; color: #222; overflow: hidden; }
#wbc-main { display: flex; height: calc(100% - 64px); }
#meshcat-pane { flex: 1 1 55%; position: relative; overflow: hidden; min-width: 200px; }
#wbc-plots { flex: 1 1 45%; overflow-y: auto; border-left: 1px solid #ccc; padding: 2px 6px; }
.wbc-plot { margin-bottom: 6px; }
.wbc-plot .title { font-weight: bold; margin: 2px 0; }
.wbc-plot .legend span { margin-right: 8px; white-space: nowrap; }
.wbc-plot canvas { width: 100%; height: 120px; display: block; cursor: crosshair; }
#wbc-bar { height: 64px; border-top: 1px solid #ccc; padding: 2px 8px; box-sizing: border-box; }
#wbc-bar .row { display: flex; align-items: center; gap: 8px; }
#wbc-marks { width: 100%; height: 16px; display: block; cursor: pointer; }
#wbc-slider { flex: 1; }
#wbc-panel { font-size: 11px; }
#wbc-state { display: none; }
"""

PAGE_SCRIPT = r"""
(function () {
  var D = window.wbcData;
  var anim = viewer.animator;
  var COLORS = __WBC_COLORS__;
  // an instant mark is a 2 px line told apart by its dash and its letter as well as its colour (each colour has a
  // contrast of 3:1 or more against the timeline's #f4f4f4 and the plots' white); a span is a translucent band
  var MARK_COLORS = {push: "rgba(224,32,27,0.18)", fall: "#d00000", end: "#d00000", safety: "#b35900",
                     operator: "#000000", command: "#2660d9", browser_push: "rgba(160,0,200,0.25)",
                     divergence: "#7a00b0"};
  var MARK_STYLES = {fall: {dash: [], letter: "F"}, end: {dash: [6, 2], letter: "E"}, safety: {dash: [4, 3],
                     letter: "S"}, operator: {dash: [1, 2], letter: "O"}, command: {dash: [6, 2, 1, 2], letter: "C"},
                     divergence: {dash: [2, 2], letter: "D"}};
  var MARKS_LEGEND = "events: push (red band), browser push (purple band), F fall (solid red line), E other end: " +
    "safety trip, operator stop, controller error (dashed red), S safety transition (dashed orange), O operator " +
    "key (dotted black), C command change (dash-dot blue), D divergence (dotted purple); the ghost run's letters " +
    "in lower case";
  var page = window.wbcPage = {t: 0, cursorT: 0, sceneT: null, playing: false, speed: 1, follow: true,
                               plots: {}, robots: D.runs.length, runs: D.runs.map(function (r) { return r.name; }),
                               marks: [], ready: false, duration: D.duration, live: !!D.live};
  var plots = [];
  var allMarks = [];
  D.runs.forEach(function (run, ri) {
    run.marks.forEach(function (m) { allMarks.push({t: m.t, kind: m.kind, label: m.label, d: m.d, run: ri}); });
  });
  (D.marks || []).forEach(function (m) { allMarks.push({t: m.t, kind: m.kind, label: m.label, d: m.d, run: -1}); });
  page.marks = allMarks.map(function (m) { return {t: m.t, kind: m.kind, label: m.label}; });

  function el(tag, attrs, parent) {
    var e = document.createElement(tag);
    for (var k in attrs) { if (k === "text") { e.textContent = attrs[k]; } else { e.setAttribute(k, attrs[k]); } }
    if (parent) { parent.appendChild(e); }
    return e;
  }

  // -- plots ---------------------------------------------------------------------------------------------------
  var box = document.getElementById("wbc-plots");
  var shape = "";
  function plotShape() {
    return JSON.stringify(D.order.map(function (key) {
      return D.runs.map(function (run) { return run.plots[key] ? Object.keys(run.plots[key].lines) : []; }); }));
  }
  function buildPlots() {
    shape = plotShape();
    box.innerHTML = "";
    plots.length = 0;
    page.plots = {};
    el("div", {"class": "wbc-plot title", text: D.title}, box);
    if (D.runs.length > 1) {
      el("div", {"class": "legend", text: D.runs.map(function (r, i) {
        return r.name + (i === 0 ? " (solid, opaque robot)" : " (dashed, translucent ghost)"); }).join("  vs  ")}, box);
    }
    D.order.forEach(buildPlot);
  }
  function buildPlot(key) {
    var series = [];
    var title = null, unit = "";
    D.runs.forEach(function (run, ri) {
      var p = run.plots[key];
      if (!p) { return; }
      title = p.title; unit = p.unit;
      Object.keys(p.lines).forEach(function (name) { series.push({run: ri, name: name, t: run.t, y: p.lines[name]}); });
    });
    if (!series.length) { return; }
    var div = el("div", {"class": "wbc-plot", id: "wbc-plot-" + key}, box);
    el("div", {"class": "title", text: title + " [" + unit + "]"}, div);
    var legend = el("div", {"class": "legend"}, div);
    var names = [];
    series.forEach(function (s) { if (names.indexOf(s.name) < 0) { names.push(s.name); } });
    names.forEach(function (n, i) {
      el("span", {style: "color:" + COLORS[i % COLORS.length], text: "\u2014 " + n}, legend);
    });
    var canvas = el("canvas", {}, div);
    var lo = Infinity, hi = -Infinity, n = 0;
    series.forEach(function (s) {
      s.color = COLORS[names.indexOf(s.name) % COLORS.length];
      s.y.forEach(function (v) { if (v !== null) { n++; if (v < lo) { lo = v; } if (v > hi) { hi = v; } } });
    });
    if (key === "torques") { lo = Math.min(lo, -1.05); hi = Math.max(hi, 1.05); }
    if (!(hi > lo)) { lo = (isFinite(lo) ? lo : 0) - 1; hi = lo + 2; }
    var pad = 0.06 * (hi - lo);
    var plot = {key: key, canvas: canvas, series: series, lo: lo - pad, hi: hi + pad, n: n, image: null};
    plots.push(plot);
    page.plots[key] = {n: n, lines: series.length};
    canvas.addEventListener("mousedown", function (ev) { scrubFrom(ev, canvas); });
  }
  buildPlots();

  function xOf(t, w) { return 40 + (w - 46) * t / Math.max(D.duration, 1e-9); }
  function tOf(x, w) { return (x - 40) / (w - 46) * D.duration; }

  function drawMarks(ctx, w, h) {
    allMarks.forEach(function (m) {
      ctx.fillStyle = ctx.strokeStyle = MARK_COLORS[m.kind] || "#555";
      var x = xOf(m.t, w);
      if (m.d > 0) { ctx.fillRect(x, 0, Math.max(2, xOf(m.t + m.d, w) - x), h); }
      else {
        var st = MARK_STYLES[m.kind] || {dash: [], letter: "?"};
        ctx.lineWidth = 2; ctx.setLineDash(st.dash); ctx.beginPath(); ctx.moveTo(x, 0);
        ctx.lineTo(x, h); ctx.stroke(); ctx.setLineDash([]);
        // the letter names the kind; the A / B ghost's (the second run's) is lower case
        ctx.font = "bold 9px sans-serif";
        ctx.fillText(m.run === 1 ? st.letter.toLowerCase() : st.letter, x + 2, 9);
      }
    });
  }

  function render(plot) {
    var c = plot.canvas, w = c.clientWidth || 400, h = c.clientHeight || 120;
    c.width = w; c.height = h;
    var ctx = c.getContext("2d");
    ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, w, h);
    drawMarks(ctx, w, h);
    function yOf(v) { return h - 4 - (h - 8) * (v - plot.lo) / (plot.hi - plot.lo); }
    ctx.fillStyle = "#555"; ctx.font = "10px sans-serif";
    ctx.fillText(plot.hi.toPrecision(3), 2, 10); ctx.fillText(plot.lo.toPrecision(3), 2, h - 2);
    ctx.strokeStyle = "#ddd"; ctx.lineWidth = 1;
    if (plot.lo < 0 && plot.hi > 0) { ctx.beginPath(); ctx.moveTo(40, yOf(0)); ctx.lineTo(w, yOf(0)); ctx.stroke(); }
    if (plot.key === "torques") {  // the limits: a line at the edge of saturation
      ctx.strokeStyle = "#e02020"; ctx.setLineDash([6, 3]);
      [-1, 1].forEach(function (v) { ctx.beginPath(); ctx.moveTo(40, yOf(v)); ctx.lineTo(w, yOf(v)); ctx.stroke(); });
      ctx.setLineDash([]);
    }
    plot.series.forEach(function (s) {
      ctx.strokeStyle = s.color; ctx.lineWidth = s.run === 0 ? 1.3 : 1.1;
      ctx.globalAlpha = s.run === 0 ? 1.0 : 0.75;
      ctx.setLineDash(s.run === 0 ? [] : [5, 3]);
      ctx.beginPath();
      var pen = false;
      for (var i = 0; i < s.t.length; i++) {
        var v = s.y[i];
        if (v === null || v === undefined) { pen = false; continue; }
        var x = xOf(s.t[i], w), y = yOf(v);
        if (pen) { ctx.lineTo(x, y); } else { ctx.moveTo(x, y); pen = true; }
      }
      ctx.stroke();
      if (plot.key === "torques") {  // saturated samples stand out
        ctx.fillStyle = "#e02020";
        for (var j = 0; j < s.t.length; j++) {
          if (s.y[j] !== null && Math.abs(s.y[j]) >= 0.999) { ctx.fillRect(xOf(s.t[j], w) - 1, yOf(s.y[j]) - 1, 3, 3); }
        }
      }
    });
    ctx.globalAlpha = 1; ctx.setLineDash([]);
    plot.image = ctx.getImageData(0, 0, w, h);
  }

  function drawCursor(plot) {
    if (!plot.image) { render(plot); }
    var c = plot.canvas, ctx = c.getContext("2d");
    ctx.putImageData(plot.image, 0, 0);
    var x = xOf(page.cursorT, c.width);
    ctx.strokeStyle = "#000"; ctx.lineWidth = 1.5;
    ctx.beginPath(); ctx.moveTo(x, 0); ctx.lineTo(x, c.height); ctx.stroke();
  }

  // -- timeline bar ----------------------------------------------------------------------------------------------
  var bar = document.getElementById("wbc-bar");
  var marksCanvas = el("canvas", {id: "wbc-marks", title: MARKS_LEGEND}, bar);
  var row = el("div", {"class": "row"}, bar);
  var playBtn = el("button", {id: "wbc-play", text: "play"}, row);
  var speedSel = el("select", {id: "wbc-speed", "aria-label": "playback speed"}, row);
  var SPEEDS = [2, 1, 0.5, 0.25, 0.1, 0.05];
  SPEEDS.forEach(function (s) {
    var o = el("option", {value: String(s), text: "x" + s}, speedSel); if (s === 1) { o.selected = true; } });
  var slider = el("input", {id: "wbc-slider", type: "range", min: "0", max: String(D.duration),
                            step: String(1 / D.fps), value: "0", "aria-label": "trial time [s]"}, row);
  var label = el("span", {id: "wbc-time", text: "0.000 s"}, row);
  var followLbl = el("label", {}, row);
  var followBox = el("input", {id: "wbc-follow", type: "checkbox"}, followLbl);
  followBox.checked = true;
  followLbl.appendChild(document.createTextNode(" follow trunk"));
  var extra = el("span", {id: "wbc-panel"}, row);
  var stateBox = el("pre", {id: "wbc-state"}, document.body);

  function drawTimeline() {
    var c = marksCanvas, w = c.clientWidth || 400, h = c.clientHeight || 16;
    c.width = w; c.height = h;
    var ctx = c.getContext("2d");
    ctx.fillStyle = "#f4f4f4"; ctx.fillRect(0, 0, w, h);
    drawMarks(ctx, w, h);
    var x = xOf(page.cursorT, w);
    ctx.fillStyle = "#000"; ctx.fillRect(x - 1, 0, 2, h);
  }

  function nearestMark(t) {
    var best = null;
    allMarks.forEach(function (m) { if (best === null || Math.abs(m.t - t) < Math.abs(best.t - t)) { best = m; } });
    return best;
  }

  function scrubFrom(ev, canvas) {
    var r = canvas.getBoundingClientRect();
    seek(tOf(ev.clientX - r.left, r.width));
  }
  marksCanvas.addEventListener("mousedown", function (ev) {
    var r = marksCanvas.getBoundingClientRect(), t = tOf(ev.clientX - r.left, r.width), m = nearestMark(t);
    seek(m && Math.abs(xOf(m.t, r.width) - (ev.clientX - r.left)) < 6 ? Math.max(0, m.t - 0.2) : t);
  });
  marksCanvas.addEventListener("mousemove", function (ev) {
    var r = marksCanvas.getBoundingClientRect(), m = nearestMark(tOf(ev.clientX - r.left, r.width));
    marksCanvas.title = m ? m.t.toFixed(3) + " s: " + m.label : "";
  });

  // -- the one clock -----------------------------------------------------------------------------------------------
  // "follow trunk": the recording poses /Cameras/follow under the trunk; the camera and the point its orbit controls
  // turn about move with it, so the robot stays framed and the person's own orbit, zoom and pan are kept. The camera's
  // frame is three.js's world (/Cameras/default stays put: meshcat's orbit controls take their target in the world)
  var followed = null;
  function follow() {
    var node = viewer.scene_tree.find(["Cameras", "follow"]), controls = viewer.controls, cam = viewer.camera;
    if (!node || !controls || !cam) { return; }
    node.object.updateMatrixWorld(true);
    var p = controls.target.clone();
    node.object.getWorldPosition(p);
    if (followed === null) { followed = controls.target.clone(); }
    if (page.follow) {
      var d = p.clone().sub(followed);
      cam.position.add(d); controls.target.add(d); controls.update(); viewer.set_dirty();
    }
    followed = p;
    page.cameraTarget = [controls.target.x, controls.target.y, controls.target.z];
  }
  function sceneReady() { return !!(anim && anim.actions && anim.actions.length > 0); }

  function publish() {
    label.textContent = page.t.toFixed(3) + " s";
    if (document.activeElement !== slider) { slider.value = String(page.t); }
    plots.forEach(drawCursor);
    drawTimeline();
    var near = allMarks.filter(function (m) { return m.t <= page.t && page.t <= m.t + Math.max(m.d, 0.3); });
    extra.textContent = near.map(function (m) { return m.label; }).join("; ");
    stateBox.textContent = JSON.stringify({t: page.t, cursorT: page.cursorT, sceneT: page.sceneT,
                                           playing: page.playing, speed: page.speed, follow: page.follow,
                                           plots: page.plots, robots: page.robots, runs: page.runs,
                                           marks: page.marks, ready: page.ready, live: page.live,
                                           duration: page.duration, cameraTarget: page.cameraTarget || null});
  }

  function seek(t) {
    t = Math.max(0, Math.min(D.duration, t));
    page.t = t; page.cursorT = t;
    if (sceneReady()) {
      if (anim.playing) { anim.pause(); }
      anim.seek(t);
      page.sceneT = anim.actions[0].time;
    }
    follow();
    publish();
  }
  page.seek = seek;

  function setPlaying(on) {
    page.playing = on && page.t < D.duration - 1e-9 || (on && D.live);
    playBtn.textContent = page.playing ? "pause" : "play";
    last = null;
    publish();
  }
  page.play = function () { setPlaying(true); };
  page.pause = function () { setPlaying(false); };
  // the speed within the menu's range (`]` stops at its fastest, `[` at its slowest); a speed between its entries
  // (``#speed=0.3``) gets an entry of its own, so that the menu shows the speed playing
  function setSpeed(s) {
    s = Math.min(SPEEDS[0], Math.max(SPEEDS[SPEEDS.length - 1], s));
    if (!(s > 0)) { s = 1; }
    page.speed = s;
    var v = String(s), known = false;
    for (var i = 0; i < speedSel.options.length; i++) { if (speedSel.options[i].value === v) { known = true; } }
    if (!known) {
      var o = document.createElement("option"); o.value = v; o.textContent = "x" + v;
      var at = null;
      for (var j = 0; j < speedSel.options.length; j++) {
        if (at === null && parseFloat(speedSel.options[j].value) < s) { at = speedSel.options[j]; } }
      speedSel.insertBefore(o, at);
    }
    speedSel.value = v; publish();
  }
  page.setSpeed = setSpeed;
  function setFollow(on) {
    page.follow = on; followBox.checked = on;
    if (on && viewer.controls) { followed = viewer.controls.target.clone(); }  // back to the trunk at once
    seek(page.t);
  }
  page.setFollow = setFollow;
  // a live page grows: its runs are replaced as the trial plays (`wbc.viz.live_page`)
  page.extend = function (data) {
    if (typeof data.duration === "number" && data.duration !== D.duration) {
      D.duration = page.duration = data.duration; slider.max = String(data.duration);
    }
    D.runs = data.runs; allMarks.length = 0;
    D.runs.forEach(function (run, ri) { run.marks.forEach(function (m) {
      allMarks.push({t: m.t, kind: m.kind, label: m.label, d: m.d, run: ri}); }); });
    page.marks = allMarks.map(function (m) { return {t: m.t, kind: m.kind, label: m.label}; });
    if (plotShape() !== shape) { buildPlots(); }
    plots.forEach(function (p) {
      var n = 0;
      p.series.forEach(function (s) {
        var pl = D.runs[s.run].plots[p.key];
        s.t = D.runs[s.run].t; s.y = pl && pl.lines[s.name] ? pl.lines[s.name] : [];
        s.y.forEach(function (v) { if (v !== null) { n++; if (v < p.lo) { p.lo = v; } if (v > p.hi) { p.hi = v; } } });
      });
      p.n = n; page.plots[p.key].n = n; p.image = null;
    });
  };

  playBtn.addEventListener("click", function () { if (!D.live) { setPlaying(!page.playing); } });
  speedSel.addEventListener("change", function () { if (!D.live) { setSpeed(parseFloat(speedSel.value)); } });
  slider.addEventListener("input", function () { seek(parseFloat(slider.value)); });
  followBox.addEventListener("change", function () { setFollow(followBox.checked); });
  document.addEventListener("keydown", function (ev) {
    var tag = ev.target && ev.target.tagName;
    if (tag === "SELECT" || (tag === "INPUT" && ev.target.type !== "range")) { return; }
    if (ev.key === " ") { setPlaying(!page.playing); ev.preventDefault(); }
    else if (ev.key === "ArrowRight") { setPlaying(false); seek(page.t + 1 / D.fps); }
    else if (ev.key === "ArrowLeft") { setPlaying(false); seek(page.t - 1 / D.fps); }
    else if (ev.key === "]") { setSpeed(page.speed * 2); }
    else if (ev.key === "[") { setSpeed(page.speed / 2); }
  });
  window.addEventListener("resize", function () { plots.forEach(function (p) { p.image = null; }); publish(); });

  var last = null;
  function frame(now) {
    if (page.playing) {
      if (last !== null) {
        var t = page.t + page.speed * (now - last) / 1000;
        if (t >= D.duration && !D.live) { t = D.duration; setPlaying(false); }
        seek(Math.min(t, D.duration));
      }
      last = now;
    }
    window.requestAnimationFrame(frame);
  }

  function post(route, body) {
    return fetch(route, {method: "POST", headers: {"Content-Type": "application/json"}, body: JSON.stringify(body)})
      .then(function (r) { return r.json(); })
      .then(function (reply) { page.lastReply = reply; extra.textContent = JSON.stringify(reply); return reply; });
  }
  page.post = post;
  function field(parent, label, id, value, width) {
    var l = el("label", {}, parent);
    l.appendChild(document.createTextNode(" " + label + " "));
    return el("input", {id: id, value: String(value), size: String(width || 4)}, l);
  }
  function num(id) { return parseFloat(document.getElementById(id).value); }
  function livePanel() {
    var row2 = el("div", {"class": "row", id: "wbc-live"}, bar);
    field(row2, "push N", "wbc-push-force", 150);
    field(row2, "towards deg", "wbc-push-heading", 90);
    field(row2, "for s", "wbc-push-duration", 0.1);
    field(row2, "at (base) m", "wbc-push-point", "0 0 0.05", 9);
    var pushBtn = el("button", {id: "wbc-push", text: "push"}, row2);
    pushBtn.addEventListener("click", function () {
      var point = document.getElementById("wbc-push-point").value.trim().split(/\s+/).map(parseFloat);
      post("push", {force_n: num("wbc-push-force"), heading_deg: num("wbc-push-heading"),
                    duration_s: num("wbc-push-duration"), point_in_base: point});
    });
    field(row2, "vx", "wbc-cmd-vx", 0); field(row2, "vy", "wbc-cmd-vy", 0); field(row2, "yaw", "wbc-cmd-yaw", 0);
    var cmdBtn = el("button", {id: "wbc-command", text: "set command"}, row2);
    cmdBtn.addEventListener("click", function () {
      post("command", {vx: num("wbc-cmd-vx"), vy: num("wbc-cmd-vy"), yaw_rate: num("wbc-cmd-yaw")});
    });
    document.getElementById("wbc-bar").style.height = "90px";
    document.getElementById("wbc-main").style.height = "calc(100% - 90px)";
    playBtn.textContent = "pause trial";
    playBtn.onclick = function (ev) {
      ev.stopImmediatePropagation();
      post("control", {pause: playBtn.textContent === "pause trial"}).then(function (r) {
        playBtn.textContent = r.paused ? "resume trial" : "pause trial"; });
    };
    speedSel.onchange = function () { post("control", {speed: parseFloat(speedSel.value)}); };
  }
  function poll() {
    fetch("state", {cache: "no-store"}).then(function (r) { return r.json(); }).then(function (s) {
      // the trial's scene came after the page (opened before the first tick) or another trial began: load it
      if (s.done || (s.scene !== undefined && s.scene !== (D.scene || 0))) { window.location.reload(); return; }
      Object.keys(s.poses).forEach(function (path) {
        var m = s.poses[path];
        viewer.handle_command({type: "set_property", path: path, property: "visible", value: m !== null});
        if (m !== null) { viewer.handle_command({type: "set_transform", path: path, matrix: new Float32Array(m)}); }
      });
      page.extend(s.data);
      page.sceneT = s.t;
      seek(s.t);
      setTimeout(poll, 200);
    }).catch(function () { setTimeout(poll, 1000); });
  }

  function start() {
    page.ready = true;
    if (D.live) { livePanel(); poll(); return; }
    if (anim) { anim.pause(); }
    var h = window.location.hash, m = /[#&]t=([0-9.]+)/.exec(h), s = /[#&]speed=([0-9.]+)/.exec(h);
    if (s) { setSpeed(parseFloat(s[1])); }
    if (/[#&]follow=0/.test(h)) { setFollow(false); }
    seek(m ? parseFloat(m[1]) : 0);
    if (!m || /[#&]play/.test(h)) { setPlaying(!m ? !!D.autoplay : true); }
    window.requestAnimationFrame(frame);
  }
  publish();
  var tries = 0;
  var timer = setInterval(function () {
    if (D.live || sceneReady() || ++tries > 100) { clearInterval(timer); start(); }
  }, 20);
})();
"""
PAGE_SCRIPT = PAGE_SCRIPT.replace("__WBC_COLORS__", json.dumps(list(OKABE_ITO)))  # the arena's plots' palette
