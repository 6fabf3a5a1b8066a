/* activebonds report: canvas player of recorded markers vs model (one-step and free run).
   Reads the JSON blob #report-data; one player per .player element (data-index). */
(function () {
  "use strict";

  var blob = document.getElementById("report-data");
  if (!blob) { return; }
  var data = JSON.parse(blob.textContent);
  var SINGLE = { oneStep: "#1f77b4", freeRun: "#ff7f0e" };
  var MULTI = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"];

  function niceStep(span, target) {
    var raw = span / Math.max(target, 1);
    var mag = Math.pow(10, Math.floor(Math.log(raw) / Math.LN10));
    var steps = [1, 2, 5, 10];
    for (var i = 0; i < steps.length; i++) {
      if (raw <= steps[i] * mag) { return steps[i] * mag; }
    }
    return 10 * mag;
  }

  function setup(el, anim) {
    var canvas = el.querySelector("canvas");
    var ctx = canvas.getContext("2d");
    var slider = el.querySelector("input.frame");
    var label = el.querySelector(".frame-label");
    var play = el.querySelector("button.play");
    var mode = el.querySelector("select.mode");
    var speed = el.querySelector("select.speed");
    var n = anim.recorded.length;
    var frame = 0;
    var timer = null;
    slider.min = 0;
    slider.max = Math.max(n - 1, 0);
    slider.value = 0;

    var zoom = el.querySelector("select.zoom");
    var W = canvas.width, H = canvas.height, M = 36;
    var scale = 1, cx = 0, cy = 0;

    function particleView(p) {
      var lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
      for (var f = 0; f < n; f++) {
        var q = anim.recorded[f][p];
        if (!ok(q)) { continue; }
        for (var k = 0; k < 2; k++) { lo[k] = Math.min(lo[k], q[k]); hi[k] = Math.max(hi[k], q[k]); }
      }
      if (!isFinite(lo[0])) { return anim.view; }
      var pad = Math.max(0.15 * Math.max(hi[0] - lo[0], hi[1] - lo[1]), 15);
      return [lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad];
    }

    function setView() {
      var v = zoom.value === "all" ? anim.view : particleView(Number(zoom.value));
      scale = Math.min((W - 2 * M) / (v[1] - v[0]), (H - 2 * M) / (v[3] - v[2]));
      cx = (v[0] + v[1]) / 2;
      cy = (v[2] + v[3]) / 2;
    }
    function px(x) { return W / 2 + (x - cx) * scale; }
    function py(y) { return H / 2 - (y - cy) * scale; }
    function ok(p) { return p !== null && p[0] !== null && p[1] !== null; }

    function colors(i) {
      if (anim.models.length === 1) { return [SINGLE.oneStep, SINGLE.freeRun]; }
      var c = MULTI[i % MULTI.length];
      return [c, c];
    }

    function grid() {
      ctx.strokeStyle = "#e6e6e6";
      ctx.fillStyle = "#777";
      ctx.lineWidth = 1;
      ctx.font = "11px sans-serif";
      var x0 = cx - (W / 2) / scale, x1 = cx + (W / 2) / scale;
      var y0 = cy - (H / 2) / scale, y1 = cy + (H / 2) / scale;
      var step = niceStep(Math.max(x1 - x0, y1 - y0), 8);
      var x, y;
      for (x = Math.ceil(x0 / step) * step; x <= x1; x += step) {
        ctx.beginPath(); ctx.moveTo(px(x), 0); ctx.lineTo(px(x), H); ctx.stroke();
        ctx.fillText(String(Math.round(x)), px(x) + 2, H - 4);
      }
      for (y = Math.ceil(y0 / step) * step; y <= y1; y += step) {
        ctx.beginPath(); ctx.moveTo(0, py(y)); ctx.lineTo(W, py(y)); ctx.stroke();
        ctx.fillText(String(Math.round(y)), 2, py(y) - 2);
      }
      ctx.fillStyle = "rgba(255,255,255,0.85)";
      ctx.fillRect(4, H - 36, 200, 16);
      ctx.fillStyle = "#333";
      ctx.fillText("horizontal " + anim.axes[0] + ", vertical " + anim.axes[1] + " (mm)", 8, H - 24);
    }

    function trails() {
      ctx.strokeStyle = "rgba(0,0,0,0.15)";
      ctx.lineWidth = 1;
      for (var p = 0; p < anim.names.length; p++) {
        ctx.beginPath();
        var pen = false;
        for (var f = 0; f < n; f++) {
          var q = anim.recorded[f][p];
          if (!ok(q)) { pen = false; continue; }
          if (pen) { ctx.lineTo(px(q[0]), py(q[1])); } else { ctx.moveTo(px(q[0]), py(q[1])); }
          pen = true;
        }
        ctx.stroke();
      }
    }

    function skeleton(pts, color, width, dash, shape, filled) {
      ctx.setLineDash(dash);
      ctx.strokeStyle = color;
      ctx.lineWidth = width;
      anim.bonds.forEach(function (b) {
        var a = pts[b[0]], c = pts[b[1]];
        if (!ok(a) || !ok(c)) { return; }
        ctx.beginPath();
        ctx.moveTo(px(a[0]), py(a[1]));
        ctx.lineTo(px(c[0]), py(c[1]));
        ctx.stroke();
      });
      ctx.setLineDash([]);
      ctx.lineWidth = 2;
      pts.forEach(function (q) {
        if (!ok(q)) { return; }
        ctx.beginPath();
        if (shape === "square") {
          ctx.rect(px(q[0]) - 6, py(q[1]) - 6, 12, 12);
        } else {
          ctx.arc(px(q[0]), py(q[1]), filled ? 5 : 7, 0, 2 * Math.PI);
        }
        if (filled) { ctx.fillStyle = color; ctx.fill(); } else { ctx.stroke(); }
      });
    }

    // The legend in the canvas's top right corner, sized to its longest label (a smaller font,
    // then an ellipsis, when that would take more than 60 % of the width): never clipped.
    // Its box [x, y, width, height] is left in the canvas's data-legend attribute.
    function legend(items) {
      var pad = 6, swatch = 24, gap = 6, maxW = Math.floor(0.6 * W);
      var size = 12, widest = 0;
      function measure() {
        ctx.font = size + "px sans-serif";
        widest = 0;
        items.forEach(function (it) { widest = Math.max(widest, ctx.measureText(it[0]).width); });
      }
      measure();
      var room = maxW - 2 * pad - swatch - gap;
      if (widest > room) {
        size = Math.max(9, Math.floor(size * room / widest));
        measure();
      }
      function fit(text) {
        if (ctx.measureText(text).width <= room) { return text; }
        while (text.length > 1 && ctx.measureText(text + "\u2026").width > room) {
          text = text.slice(0, -1);
        }
        return text + "\u2026";
      }
      var rowH = size + 5;
      var w = Math.ceil(Math.min(widest, room) + 2 * pad + swatch + gap);
      var h = items.length * rowH + 2 * pad - 4;
      var x0 = W - 4 - w, y0 = 4;
      ctx.fillStyle = "rgba(255,255,255,0.85)";
      ctx.fillRect(x0, y0, w, h);
      var y = y0 + pad + size - 2;
      items.forEach(function (it) {
        ctx.strokeStyle = it[1];
        ctx.lineWidth = 2;
        ctx.setLineDash(it[2]);
        var mid = y - Math.round(size / 3);
        ctx.beginPath(); ctx.moveTo(x0 + pad, mid); ctx.lineTo(x0 + pad + swatch, mid); ctx.stroke();
        ctx.setLineDash([]);
        ctx.fillStyle = "#222";
        ctx.fillText(fit(it[0]), x0 + pad + swatch + gap, y);
        y += rowH;
      });
      canvas.setAttribute("data-legend", [x0, y0, w, h].join(","));
    }

    function draw() {
      ctx.setTransform(1, 0, 0, 1, 0, 0);
      ctx.clearRect(0, 0, W, H);
      ctx.fillStyle = "#ffffff";
      ctx.fillRect(0, 0, W, H);
      grid();
      trails();
      var show = mode.value;
      var items = [["recorded", "#000000", []]];
      skeleton(anim.recorded[frame], "#000000", 3, [], "circle", true);
      anim.models.forEach(function (m, i) {
        var c = colors(i);
        var pre = anim.models.length > 1 ? m.label + " " : "";
        if (show !== "free") {
          skeleton(m.one_step[frame], c[0], 1.5, [], "circle", false);
          items.push([pre + "one-step", c[0], []]);
        }
        if (show !== "one") {
          skeleton(m.free_run[frame], c[1], 1.5, [6, 4], "square", false);
          items.push([pre + "free run", c[1], [6, 4]]);
        }
      });
      ctx.font = "11px sans-serif";
      ctx.fillStyle = "#000";
      anim.recorded[frame].forEach(function (q, p) {
        if (ok(q)) { ctx.fillText(anim.names[p], px(q[0]) + 8, py(q[1]) - 8); }
      });
      legend(items);
      var fn = anim.frame_numbers[frame];
      var fitEnd = anim.fit_end !== undefined ? anim.fit_end : anim.fit_frames;
      var where = fn < fitEnd ? "fitted window" : "beyond the fit (generalisation)";
      label.textContent = "frame " + fn + " / " + anim.frame_numbers[n - 1] +
        "  \u00b7  t = " + anim.times[frame].toFixed(3) + " s  \u00b7  " + where;
    }

    function setFrame(f) {
      frame = ((f % n) + n) % n;
      slider.value = frame;
      draw();
    }

    function stop() {
      if (timer !== null) { clearInterval(timer); timer = null; }
      play.textContent = "\u25b6 play";
      play.setAttribute("aria-pressed", "false");
    }

    function start() {
      stop();
      timer = setInterval(function () { setFrame(frame + 1); }, 1000 / Number(speed.value));
      play.textContent = "\u275a\u275a pause";
      play.setAttribute("aria-pressed", "true");
    }

    play.addEventListener("click", function () { if (timer === null) { start(); } else { stop(); } });
    slider.addEventListener("input", function () { stop(); setFrame(Number(slider.value)); });
    mode.addEventListener("change", draw);
    zoom.addEventListener("change", function () { setView(); draw(); });
    anim.names.forEach(function (name, p) {
      var opt = document.createElement("option");
      opt.value = String(p);
      opt.textContent = "around " + name;
      zoom.appendChild(opt);
    });
    setView();
    speed.addEventListener("change", function () { if (timer !== null) { start(); } });
    setFrame(0);
  }

  var players = document.querySelectorAll(".player");
  for (var i = 0; i < players.length; i++) {
    setup(players[i], data.animations[Number(players[i].getAttribute("data-index"))]);
  }
})();
