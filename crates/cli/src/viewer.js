// irmirror's 3-D view: draws the meshes of window.IRMIRROR_SCENE (scene.js beside the report)
// with WebGL, offline. Drag to turn about the scene's up, wheel to zoom, shift-drag to pan.
// After each draw the canvas records how many pixels it coloured (data-drawn-pixels), so a
// headless browser can check that the view rendered.
(function () {
  "use strict";
  var scene = window.IRMIRROR_SCENE;
  var canvas = document.getElementById("irmirror-3d");
  var panel = document.getElementById("irmirror-3d-parts");
  if (!scene || !canvas) { return; }
  var gl = canvas.getContext("webgl", { preserveDrawingBuffer: true, antialias: true });
  if (!gl) { canvas.insertAdjacentHTML("afterend", "<p>This browser has no WebGL: open scene.glb in a glTF viewer instead.</p>"); return; }
  if (!gl.getExtension("OES_element_index_uint")) { throw new Error("WebGL lacks 32-bit indices"); }

  function bytes(b64) {
    var s = atob(b64), out = new Uint8Array(s.length);
    for (var i = 0; i < s.length; i++) { out[i] = s.charCodeAt(i); }
    return out.buffer;
  }
  function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
  function add(a, b) { return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]; }
  function scale(a, k) { return [a[0] * k, a[1] * k, a[2] * k]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function norm(a) { var l = Math.sqrt(dot(a, a)) || 1; return scale(a, 1 / l); }

  var vs = "attribute vec3 p; attribute vec3 n; uniform mat4 m; varying vec3 vn; varying vec3 vp;" +
    "void main(){ vn = n; vp = p; gl_Position = m * vec4(p, 1.0); }";
  var fs = "precision mediump float; varying vec3 vn; varying vec3 vp; uniform vec4 c; uniform vec3 eye;" +
    "void main(){ vec3 l = normalize(eye - vp); float d = abs(dot(normalize(vn), l));" +
    " gl_FragColor = vec4(c.rgb * (0.3 + 0.7 * d), c.a); }";
  function shader(type, src) {
    var s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) { throw new Error(gl.getShaderInfoLog(s)); }
    return s;
  }
  var prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER, vs));
  gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, fs));
  gl.linkProgram(prog);
  var loc = { p: gl.getAttribLocation(prog, "p"), n: gl.getAttribLocation(prog, "n"),
    m: gl.getUniformLocation(prog, "m"), c: gl.getUniformLocation(prog, "c"), eye: gl.getUniformLocation(prog, "eye") };

  var lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  var parts = scene.parts.map(function (part) {
    var pos = new Float32Array(bytes(part.positions));
    var idx = part.index_bits === 16 ? new Uint16Array(bytes(part.indices)) : new Uint32Array(bytes(part.indices));
    var nrm = new Float32Array(pos.length);
    for (var t = 0; t < idx.length; t += 3) {
      var a = idx[t] * 3, b = idx[t + 1] * 3, c = idx[t + 2] * 3;
      var e1 = [pos[b] - pos[a], pos[b + 1] - pos[a + 1], pos[b + 2] - pos[a + 2]];
      var e2 = [pos[c] - pos[a], pos[c + 1] - pos[a + 1], pos[c + 2] - pos[a + 2]];
      var f = cross(e1, e2);
      [a, b, c].forEach(function (v) { nrm[v] += f[0]; nrm[v + 1] += f[1]; nrm[v + 2] += f[2]; });
    }
    if (part.frame) {
      for (var i = 0; i < pos.length; i += 3) {
        for (var k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], pos[i + k]); hi[k] = Math.max(hi[k], pos[i + k]); }
      }
    }
    var bp = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, bp); gl.bufferData(gl.ARRAY_BUFFER, pos, gl.STATIC_DRAW);
    var bn = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, bn); gl.bufferData(gl.ARRAY_BUFFER, nrm, gl.STATIC_DRAW);
    var bi = gl.createBuffer(); gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, bi); gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
    return { name: part.name, colour: part.colour, visible: part.visible, bp: bp, bn: bn, bi: bi, count: idx.length,
      type: part.index_bits === 16 ? gl.UNSIGNED_SHORT : gl.UNSIGNED_INT };
  });
  if (!isFinite(lo[0])) { lo = [-1, -1, -1]; hi = [1, 1, 1]; }

  var up = norm(scene.up);
  var target = scale(add(lo, hi), 0.5);
  var radius = Math.max(0.5, Math.sqrt(dot(sub(hi, lo), sub(hi, lo))));
  // Start looking from the cameras' side, a little above.
  var side = cross(up, [1, 0, 0]);
  side = norm(dot(side, side) > 1e-6 ? side : cross(up, [0, 0, 1]));
  var start = norm(sub([0, 0, 0], target));
  var yaw = Math.atan2(dot(start, cross(up, side)), dot(start, side)), pitch = 0.35, dist = 1.3 * radius;

  function view() {
    var fwd0 = norm(cross(up, side)), right0 = side;
    var dir = add(scale(add(scale(right0, Math.cos(yaw)), scale(fwd0, Math.sin(yaw))), Math.cos(pitch)), scale(up, Math.sin(pitch)));
    var eye = add(target, scale(dir, dist));
    var z = norm(sub(eye, target)), x = norm(cross(up, z)), y = cross(z, x);
    var v = [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
    var aspect = canvas.width / canvas.height, near = dist * 0.01, far = dist * 10, f = 1 / Math.tan(0.4);
    var p = [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, 2 * far * near / (near - far), 0];
    var m = new Float32Array(16);
    for (var c = 0; c < 4; c++) {
      for (var r = 0; r < 4; r++) {
        var s = 0;
        for (var k = 0; k < 4; k++) { s += p[k * 4 + r] * v[c * 4 + k]; }
        m[c * 4 + r] = s;
      }
    }
    return { m: m, eye: eye };
  }

  function draw() {
    var vw = view();
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(1, 1, 1, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(prog);
    gl.uniformMatrix4fv(loc.m, false, vw.m);
    gl.uniform3fv(loc.eye, vw.eye);
    [false, true].forEach(function (blended) {
      parts.forEach(function (pt) {
        if (!pt.visible || (pt.colour[3] < 1) !== blended) { return; }
        if (blended) { gl.enable(gl.BLEND); gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA); gl.depthMask(false); }
        gl.uniform4fv(loc.c, pt.colour);
        gl.bindBuffer(gl.ARRAY_BUFFER, pt.bp); gl.enableVertexAttribArray(loc.p); gl.vertexAttribPointer(loc.p, 3, gl.FLOAT, false, 0, 0);
        gl.bindBuffer(gl.ARRAY_BUFFER, pt.bn); gl.enableVertexAttribArray(loc.n); gl.vertexAttribPointer(loc.n, 3, gl.FLOAT, false, 0, 0);
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, pt.bi);
        gl.drawElements(gl.TRIANGLES, pt.count, pt.type, 0);
        gl.disable(gl.BLEND); gl.depthMask(true);
      });
    });
    var px = new Uint8Array(canvas.width * canvas.height * 4), drawn = 0;
    gl.readPixels(0, 0, canvas.width, canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, px);
    for (var i = 0; i < px.length; i += 4) { if (px[i] < 250 || px[i + 1] < 250 || px[i + 2] < 250) { drawn++; } }
    canvas.setAttribute("data-drawn-pixels", String(drawn));
  }

  parts.forEach(function (pt) {
    var label = document.createElement("label");
    var box = document.createElement("input");
    box.type = "checkbox"; box.checked = pt.visible;
    box.onchange = function () { pt.visible = box.checked; draw(); };
    var swatch = "rgb(" + pt.colour.slice(0, 3).map(function (c) { return Math.round(255 * c); }).join(",") + ")";
    label.innerHTML = " <span style=\"color:" + swatch + "\">&#9632;</span> " + pt.name + " ";
    label.insertBefore(box, label.firstChild);
    if (panel) { panel.appendChild(label); }
  });

  var drag = null;
  canvas.addEventListener("mousedown", function (e) { drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey }; });
  window.addEventListener("mouseup", function () { drag = null; });
  window.addEventListener("mousemove", function (e) {
    if (!drag) { return; }
    var dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      var vw = view(), z = norm(sub(vw.eye, target)), x = norm(cross(up, z)), y = cross(z, x);
      target = add(target, add(scale(x, -dx * dist * 0.002), scale(y, dy * dist * 0.002)));
    } else {
      yaw -= dx * 0.01;
      pitch = Math.max(-1.5, Math.min(1.5, pitch + dy * 0.01));
    }
    draw();
  });
  canvas.addEventListener("wheel", function (e) { e.preventDefault(); dist *= Math.exp(e.deltaY * 0.001); draw(); }, { passive: false });
  draw();
})();
