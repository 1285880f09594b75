"""An interactive 3D view of the exported animations in the run report (three.js, offline).

The export stage writes each variant (the FEM skin, the captured scan) as a glTF binary with
morph targets and animated weights. The viewer plays them with three.js: play and pause, a
frame slider, orbit (drag), zoom (wheel), and a switch between the variants. three.js comes
from Debian's ``libjs-three`` (r111: its GLTFLoader reads KHR_mesh_quantization), copied
beside the page, so the report needs no network when it is viewed; npm is not available
to this project. Browsers refuse to fetch files from a ``file://`` page, so each .glb is
written as a script that assigns its bytes in base64 (an extra third in size).

Where the run has a ground truth, each vertex can be coloured by its error against it (the
largest over the frames, the captured-scan tiles' colour map): the "error" switch, or
``#error=1`` in the URL. The page reports its state in the element ``#status`` ("ready:
...") and takes the frame to show from the URL (``viewer.html#frame=21``; without it, it
plays), so a headless browser can check it (``tests/render/test_viewer.py``).
"""

from __future__ import annotations

import base64
import json
import shutil
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

#: Where Debian's libjs-three puts three.js, and the three scripts the viewer needs.
THREE_DIR = Path("/usr/share/javascript/three")
SCRIPTS = (
    "three.min.js",
    "examples/js/loaders/GLTFLoader.js",
    "examples/js/controls/OrbitControls.js",
)
#: What to install when three.js is missing.
THREE_MISSING = f"no three.js in {THREE_DIR}: install Debian's libjs-three (make setup-system)"


def three_available(root: Path = THREE_DIR) -> bool:
    """Whether every script of :data:`SCRIPTS` is under ``root``."""
    return all((root / s).is_file() for s in SCRIPTS)


def write_viewer(
    out_dir: Path,
    models: dict[str, Path],
    root: Path = THREE_DIR,
    colours: dict[str, tuple[NDArray, str]] | None = None,
) -> Path:
    """``out_dir/viewer.html`` playing the glTF binaries ``models`` (label -> .glb path, the
    first shown first; each frame at its key time), with its scripts in ``out_dir/viewer/``
    (three.js from ``root``). ``colours``: label -> (N, 3) uint8 sRGB per vertex of that
    model and the legend they mean (the error against the truth), shown with a switch; a
    model whose vertex count differs is shown plain and the status says so.
    FileNotFoundError names what is missing (three.js, a model)."""
    if not three_available(root):
        raise FileNotFoundError(THREE_MISSING)
    missing = [str(p) for p in models.values() if not Path(p).is_file()]
    if missing:
        raise FileNotFoundError(f"viewer: no glTF file {', '.join(missing)}")
    assets = out_dir / "viewer"
    assets.mkdir(parents=True, exist_ok=True)
    for script in SCRIPTS:
        shutil.copyfile(root / script, assets / Path(script).name)
    names = []
    for i, (label, path) in enumerate(models.items()):
        name = f"model{i}.glb.js"
        data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
        text = "window.PHYSANIM_GLB = window.PHYSANIM_GLB || {};\n"
        text += f"window.PHYSANIM_GLB[{json.dumps(label)}] = {json.dumps(data)};\n"
        if colours and label in colours:
            rgb, legend = colours[label]
            packed = base64.b64encode(np.ascontiguousarray(rgb, np.uint8).tobytes()).decode()
            text += "window.PHYSANIM_COLOURS = window.PHYSANIM_COLOURS || {};\n"
            text += f"window.PHYSANIM_COLOURS[{json.dumps(label)}] = "
            text += f"{json.dumps({'rgb': packed, 'legend': legend})};\n"
        (assets / name).write_text(text)
        names.append(name)
    tags = "".join(
        f"<script src='viewer/{n}'></script>" for n in [Path(s).name for s in SCRIPTS] + names
    )
    page = out_dir / "viewer.html"
    page.write_text(
        _PAGE.replace("__SCRIPTS__", tags).replace("__LABELS__", json.dumps(list(models)))
    )
    return page


_PAGE = """<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>
<title>physanim: 3D viewer</title>
<style>
 html, body { margin: 0; height: 100%; background: #20242a; color: #e8e8e8;
   font: 14px system-ui, sans-serif; overflow: hidden; }
 #bar { position: absolute; left: 0; right: 0; bottom: 0; padding: 8px 12px;
   background: rgba(0, 0, 0, 0.45); display: flex; gap: 12px; align-items: center; }
 #frame { flex: 1; }
 button, select { font: inherit; }
 #status { position: absolute; left: 12px; top: 8px; opacity: 0.8; }
</style></head><body>
<div id='status'>loading</div>
<div id='bar'>
 <button id='play'>pause</button>
 <input id='frame' type='range' min='0' max='0' step='1' value='0'>
 <span id='label'>frame 0</span>
 <select id='model'></select>
 <label id='errorbox' hidden><input id='error' type='checkbox'> error</label>
 <span id='legend'></span>
</div>
__SCRIPTS__
<script>
(function () {
  var labels = __LABELS__;
  var status = document.getElementById('status');
  var renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  document.body.insertBefore(renderer.domElement, document.body.firstChild);
  var scene = new THREE.Scene();
  scene.background = new THREE.Color(0x20242a);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x404050, 0.75));
  var key = new THREE.DirectionalLight(0xffffff, 0.7);
  key.position.set(-0.3, 0.5, 1.0);
  scene.add(key);
  var camera = new THREE.PerspectiveCamera(20, 1, 0.01, 10);
  var controls = new THREE.OrbitControls(camera, renderer.domElement);
  var models = [], current = 0, times = [0], playing = true, frame = 0, clock = 0;
  var slider = document.getElementById('frame'), play = document.getElementById('play');
  var text = document.getElementById('label'), pick = document.getElementById('model');
  var hash = /frame=(\\d+)/.exec(window.location.hash);
  var errorBox = document.getElementById('error'), legend = document.getElementById('legend');
  var colouring = /error=1/.test(window.location.hash), notes = [];

  function resize() {
    renderer.setSize(window.innerWidth, window.innerHeight);
    camera.aspect = window.innerWidth / Math.max(window.innerHeight, 1);
    camera.updateProjectionMatrix();
  }
  function bytes(b64) {
    var raw = atob(b64), out = new Uint8Array(raw.length);
    for (var i = 0; i < raw.length; i++) out[i] = raw.charCodeAt(i);
    return out.buffer;
  }
  function paint() {
    models.forEach(function (m) {
      m.meshes.forEach(function (o) {
        o.material = colouring && o.userData.errorMaterial ? o.userData.errorMaterial
                                                           : o.userData.plainMaterial;
      });
    });
    var c = window.PHYSANIM_COLOURS && window.PHYSANIM_COLOURS[labels[current]];
    legend.textContent = colouring && c ? c.legend : '';
  }
  function show(f) {
    frame = Math.max(0, Math.min(times.length - 1, f));
    models.forEach(function (m, i) {
      m.root.visible = i === current;
      if (m.action) { m.action.paused = false; m.action.enabled = true; }  // held at the end
      m.mixer.setTime(times[frame]);
    });
    slider.value = frame;
    text.textContent = 'frame ' + frame + ' (' + times[frame].toFixed(2) + ' s)';
  }
  function frameCamera(root) {
    // the base shape's box: three.js r111 reads quantized morph targets raw on the CPU, so
    // the geometry's own bounds (and its frustum culling) would be off by the int16 range
    root.updateMatrixWorld(true);
    var box = new THREE.Box3();
    root.traverse(function (o) {
      if (o.isMesh) {
        box.union(new THREE.Box3().setFromBufferAttribute(o.geometry.attributes.position)
          .applyMatrix4(o.matrixWorld));
      }
    });
    var centre = box.getCenter(new THREE.Vector3());
    var size = box.getSize(new THREE.Vector3()).length();
    camera.position.set(centre.x, centre.y, centre.z + 2.6 * size);
    camera.near = size / 50; camera.far = size * 50; camera.updateProjectionMatrix();
    controls.target.copy(centre); controls.update();
  }
  function loaded() {
    labels.forEach(function (l, i) {
      var o = document.createElement('option'); o.value = i; o.textContent = l; pick.appendChild(o);
    });
    times = models[0].times;
    slider.max = times.length - 1;
    frameCamera(models[0].root);
    if (window.PHYSANIM_COLOURS) { document.getElementById('errorbox').hidden = false; }
    errorBox.checked = colouring;
    paint();
    if (hash) { playing = false; play.textContent = 'play'; show(parseInt(hash[1], 10)); }
    else show(0);
    status.textContent = 'ready: ' + models.length + ' models, ' + times.length + ' frames' +
      (colouring ? ', error colours' : '') + notes.join('');
  }
  labels.forEach(function (label, i) {
    new THREE.GLTFLoader().parse(bytes(window.PHYSANIM_GLB[label]), '', function (gltf) {
      var root = gltf.scene, meshes = [];
      var given = window.PHYSANIM_COLOURS && window.PHYSANIM_COLOURS[label];
      root.traverse(function (o) {
        if (o.isMesh) {
          o.frustumCulled = false;
          var look = {roughness: 0.75, side: THREE.DoubleSide, morphTargets: true,
                      morphNormals: !!o.geometry.morphAttributes.normal};
          o.userData.plainMaterial = new THREE.MeshStandardMaterial(
            Object.assign({color: 0xe0cfb1}, look));
          if (given) {
            var rgb = new Uint8Array(bytes(given.rgb));
            if (rgb.length === 3 * o.geometry.attributes.position.count) {
              o.geometry.setAttribute('color', new THREE.BufferAttribute(rgb, 3, true));
              o.userData.errorMaterial = new THREE.MeshStandardMaterial(
                Object.assign({color: 0xffffff, vertexColors: THREE.VertexColors}, look));
            } else {
              notes.push('; ' + label + ': ' + (rgb.length / 3) + ' colours for ' +
                         o.geometry.attributes.position.count + ' vertices, shown plain');
            }
          }
          o.material = o.userData.plainMaterial;
          meshes.push(o);
        }
      });
      var mixer = new THREE.AnimationMixer(root), clip = gltf.animations[0];
      var action = null;
      if (clip) {  // played once and held: a repeating action wraps the last frame to the first
        action = mixer.clipAction(clip);
        action.setLoop(THREE.LoopOnce);
        action.clampWhenFinished = true;
        action.play();
      }
      scene.add(root);
      models[i] = {root: root, mixer: mixer, action: action, meshes: meshes,
                   times: clip ? Array.prototype.slice.call(clip.tracks[0].times) : [0]};
      if (models.filter(Boolean).length === labels.length) loaded();
    }, function (err) { status.textContent = 'error: ' + (err.message || err); });
  });
  play.onclick = function () { playing = !playing; play.textContent = playing ? 'pause' : 'play'; };
  slider.oninput = function () { playing = false; play.textContent = 'play'; show(+slider.value); };
  pick.onchange = function () { current = +pick.value; paint(); show(frame); };
  errorBox.onchange = function () { colouring = errorBox.checked; paint(); };
  window.addEventListener('resize', resize);
  resize();
  var last = null;
  renderer.setAnimationLoop(function (t) {
    if (playing && models.length && last !== null) {
      var end = times[times.length - 1];
      clock = end > 0 ? (clock + (t - last) / 1000) % end : 0;
      var f = 0;
      while (f + 1 < times.length && times[f + 1] <= clock) f++;
      show(f);
    }
    last = t;
    renderer.render(scene, camera);
  });
})();
</script></body></html>
"""
