// The plenoxd map viewer. Runs on Debian's three.js r111 (the THREE global, and
// THREE.OrbitControls and THREE.GLTFLoader from its examples), loaded by index.html from the
// same server.
//
// It polls the server's JSON (web/viewer_routes.h): the map list every 2 s, the selected map's
// SLAM cameras and keyframes every 0.5 s, and fetches the map's point cloud (PLY) or mesh (glTF
// at a level of detail), as the Points / Mesh toggle says, again only when its version changed. Cameras follow OpenCV's convention (x right, y down, z forward);
// three.js cameras look down -z with y up, so the two differ by a half turn about x.
(function () {
  'use strict';

  const TRACK_COLORS = [0xff2bd6, 0x2bff88, 0xffa62b, 0x2bd9ff, 0xb388ff, 0xff5252];
  const KEYFRAME_COLOR = 0xffe14d;
  const LOOP_COLOR = 0xffffff;  // loop-closure edges between keyframes
  const MAPS_EVERY_MS = 2000;
  const TRAJECTORY_EVERY_MS = 500;
  const POINTS_MIN_INTERVAL_MS = 1500;  // while a map grows, at most one cloud per 1.5 s
  const MESH_MIN_INTERVAL_MS = 5000;    // and one mesh per 5 s (marching cubes on the device)
  const RENDER_WIDTH = 320, RENDER_HEIGHT = 240, RENDER_FOV = 50;
  // OpenCV camera -> three.js camera: a half turn about x.
  const CV_TO_GL = new THREE.Quaternion(1, 0, 0, 0);

  const $ = (id) => document.getElementById(id);
  const body = document.body;

  // ---------------------------------------------------------------------------------------
  // The bearer token: given once as /viewer/#token=T (a fragment never reaches a server log),
  // kept for this tab in sessionStorage, and removed from the address bar.
  function takeTokenFromUrl() {
    const hash = new URLSearchParams(location.hash.slice(1));
    const query = new URLSearchParams(location.search);
    const token = hash.get('token') || query.get('token');
    if (token) {
      sessionStorage.setItem('plenoxd-token', token);
      hash.delete('token');
      query.delete('token');
      const rest = hash.toString();
      const search = query.toString();
      history.replaceState(null, '', location.pathname + (search ? '?' + search : '') +
                           (rest ? '#' + rest : ''));
    }
  }
  takeTokenFromUrl();

  function headers() {
    const token = sessionStorage.getItem('plenoxd-token');
    return token ? { Authorization: 'Bearer ' + token } : {};
  }

  class HttpError extends Error {
    constructor(status, message) { super(message); this.status = status; }
  }

  async function get(path, kind) {
    const response = await fetch(path, { headers: headers(), cache: 'no-store' });
    if (!response.ok) {
      let message = response.statusText;
      try { message = (await response.json()).error || message; } catch (e) { /* not JSON */ }
      throw new HttpError(response.status, message);
    }
    if (kind === 'json') return response.json();
    if (kind === 'blob') return response.blob();
    return response.arrayBuffer();
  }

  function api(endpoint, params) {
    return '/viewer/api/' + endpoint + (params ? '?' + new URLSearchParams(params) : '');
  }

  // ---------------------------------------------------------------------------------------
  // PLY (binary little endian): the point clouds, and meshes (vertex + face lists).
  const PLY_TYPES = {
    char: ['getInt8', 1], int8: ['getInt8', 1], uchar: ['getUint8', 1], uint8: ['getUint8', 1],
    short: ['getInt16', 2], int16: ['getInt16', 2], ushort: ['getUint16', 2],
    uint16: ['getUint16', 2], int: ['getInt32', 4], int32: ['getInt32', 4],
    uint: ['getUint32', 4], uint32: ['getUint32', 4], float: ['getFloat32', 4],
    float32: ['getFloat32', 4], double: ['getFloat64', 8], float64: ['getFloat64', 8],
  };

  // Interleaves PLY vertex columns (x, y, z or red, green, blue) into one typed array, as a
  // three.js BufferAttribute wants them.
  function interleave(vertex, names, ArrayType) {
    const n = vertex.count, k = names.length;
    const out = new ArrayType(k * n);
    names.forEach((name, j) => {
      const column = vertex.cols[name];
      for (let i = 0; i < n; ++i) out[k * i + j] = column[i];
    });
    return out;
  }

  function parsePly(buffer) {
    const bytes = new Uint8Array(buffer);
    const marker = 'end_header\n';
    let end = -1;
    const limit = Math.min(bytes.length, 65536);
    let text = '';
    for (let i = 0; i < limit; ++i) text += String.fromCharCode(bytes[i]);
    end = text.indexOf(marker);
    if (!text.startsWith('ply\n') || end < 0) throw new Error('not a PLY file');
    const elements = [];
    for (const line of text.slice(0, end).split('\n')) {
      const w = line.trim().split(/\s+/);
      if (w[0] === 'format' && w[1] !== 'binary_little_endian') {
        throw new Error('PLY: only binary_little_endian is read');
      } else if (w[0] === 'element') {
        elements.push({ name: w[1], count: parseInt(w[2], 10), props: [] });
      } else if (w[0] === 'property' && elements.length) {
        const props = elements[elements.length - 1].props;
        if (w[1] === 'list') props.push({ name: w[4], list: true, countType: w[2], itemType: w[3] });
        else props.push({ name: w[2], type: w[1] });
      }
    }
    const view = new DataView(buffer);
    let offset = end + marker.length;
    const out = {};
    for (const el of elements) {
      const fixed = el.props.every((p) => !p.list);
      const cols = {};
      if (fixed) {
        let stride = 0;
        const layout = el.props.map((p) => {
          const [getter, size] = PLY_TYPES[p.type];
          const at = stride; stride += size;
          const array = new Float32Array(el.count);
          cols[p.name] = array;
          return { getter, at, array };
        });
        if (offset + stride * el.count > buffer.byteLength) throw new Error('PLY: truncated');
        for (let i = 0; i < el.count; ++i, offset += stride) {
          for (const c of layout) c.array[i] = view[c.getter](offset + c.at, true);
        }
      } else {
        // Faces: one list of vertex indices each; triangles are kept, polygons fanned.
        const indices = [];
        for (let i = 0; i < el.count; ++i) {
          for (const p of el.props) {
            if (!p.list) { offset += PLY_TYPES[p.type][1]; continue; }
            const [countGet, countSize] = PLY_TYPES[p.countType];
            const [itemGet, itemSize] = PLY_TYPES[p.itemType];
            const n = view[countGet](offset, true); offset += countSize;
            const first = view[itemGet](offset, true);
            for (let k = 2; k < n; ++k) {
              indices.push(first, view[itemGet](offset + (k - 1) * itemSize, true),
                           view[itemGet](offset + k * itemSize, true));
            }
            offset += n * itemSize;
          }
        }
        cols.indices = indices;
      }
      out[el.name] = { count: el.count, cols };
    }
    return out;
  }

  // ---------------------------------------------------------------------------------------
  // The scene.
  const container = $('scene');
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(0x15181d);
  container.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(50, 1, 0.01, 1000);
  camera.up.set(0, 0, 1);
  camera.position.set(3, 3, 3);
  const controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.enableDamping = false;
  const mapGroup = new THREE.Group();       // points or mesh
  const slamGroup = new THREE.Group();      // cameras, paths, keyframes
  scene.add(mapGroup, slamGroup);
  scene.add(new THREE.AmbientLight(0xffffff, 0.55));
  const sun = new THREE.DirectionalLight(0xffffff, 0.6);
  sun.position.set(1, 2, 3);
  scene.add(sun);

  function resize() {
    const w = container.clientWidth, h = container.clientHeight;
    if (w === 0 || h === 0) return;
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }
  window.addEventListener('resize', resize);
  resize();

  let framesDrawn = 0;
  function animate() {
    requestAnimationFrame(animate);
    controls.update();
    renderer.render(scene, camera);
    if (state.cloud) body.dataset.framesDrawn = String(++framesDrawn);
  }

  // ---------------------------------------------------------------------------------------
  // State.
  const state = {
    maps: [],
    selected: null,       // map name
    voxel: 0.02,
    mode: 'points',       // what the map is shown as: 'points' or 'mesh'
    loadedVersion: -1,    // version of the cloud or mesh shown (or refused as too large)
    loadedMode: null,     // what loadedVersion was loaded as
    loadingPoints: false,
    lastPointsAt: 0,
    cloud: null,          // THREE.Points or THREE.Mesh: the map as shown
    fitted: false,        // the view was framed on this map's cloud
    bounds: null,         // THREE.Sphere of the cloud
    trajectory: null,
    loadingTrajectory: false,
    pickables: [],        // meshes a click may hit, each with userData.pose
  };

  function setStatus(text, error) {
    const s = $('status');
    s.textContent = text;
    s.className = error ? 'error' : 'muted';
  }

  function showTokenForm() {
    $('token-form').hidden = false;
    setStatus('this plenoxd needs its token (see the left panel)', true);
  }
  $('token-form').addEventListener('submit', (e) => {
    e.preventDefault();
    sessionStorage.setItem('plenoxd-token', $('token').value.trim());
    $('token-form').hidden = true;
    pollMaps();
  });

  function handleError(e, what) {
    if (e instanceof HttpError && e.status === 401) showTokenForm();
    else setStatus(what + ': ' + e.message, true);
  }

  // ---------------------------------------------------------------------------------------
  // Maps.
  function selectedFromHash() {
    return new URLSearchParams(location.hash.slice(1)).get('map');
  }

  function selectMap(name) {
    if (state.selected === name) return;
    state.selected = name;
    state.loadedVersion = -1;
    state.fitted = false;
    state.trajectory = null;
    clearGroup(mapGroup);
    clearGroup(slamGroup);
    state.cloud = null;
    body.dataset.map = name;
    body.dataset.points = '0';
    body.dataset.faces = '0';
    const hash = new URLSearchParams(location.hash.slice(1));
    hash.set('map', name);
    history.replaceState(null, '', location.pathname + location.search + '#' + hash);
    renderMapList();
    pollTrajectory();
  }

  function renderMapList() {
    const list = $('maps');
    list.textContent = '';
    if (state.maps.length === 0) {
      const li = document.createElement('li');
      li.className = 'muted';
      li.textContent = 'no maps yet';
      list.appendChild(li);
    }
    for (const m of state.maps) {
      const li = document.createElement('li');
      if (m.name === state.selected) li.className = 'selected';
      const name = document.createElement('div');
      name.textContent = m.name + (m.mapping ? ' ●' : '');
      const meta = document.createElement('div');
      meta.className = 'meta small';
      meta.textContent = 'v' + m.version + ' · ' + m.keyframes + ' kf · ' +
          (m.memory_bytes / 1048576).toFixed(1) + ' MB';
      li.append(name, meta);
      li.addEventListener('click', () => selectMap(m.name));
      list.appendChild(li);
    }
  }

  async function pollMaps() {
    try {
      const answer = await get(api('maps'), 'json');
      $('title').textContent = answer.title;
      document.title = answer.title + ' · viewer';
      state.maps = answer.maps;
      body.dataset.maps = String(answer.maps.length);
      const wanted = selectedFromHash();
      const names = answer.maps.map((m) => m.name);
      if (state.selected === null || !names.includes(state.selected)) {
        if (wanted && names.includes(wanted)) selectMap(wanted);
        else if (names.length) selectMap(names[0]);
      }
      renderMapList();
      const current = answer.maps.find((m) => m.name === state.selected);
      if (current) {
        state.voxel = current.voxel_size || state.voxel;
        maybeLoadPoints(current);
      } else {
        setStatus('no maps yet: integrate or run SLAM into one');
      }
    } catch (e) {
      handleError(e, 'maps');
    }
  }

  // ---------------------------------------------------------------------------------------
  // Points.
  function clearGroup(group) {
    for (const child of [...group.children]) {
      group.remove(child);
      child.traverse((o) => {
        if (o.geometry) o.geometry.dispose();
        if (o.material) o.material.dispose();
      });
    }
  }

  function pointSize() {
    return state.voxel * parseFloat($('point-size').value);
  }

  async function maybeLoadPoints(info) {
    const now = performance.now();
    const mode = state.mode;
    if (state.loadingPoints) return;
    if (info.version === state.loadedVersion && mode === state.loadedMode) return;
    const interval = mode === 'mesh' ? MESH_MIN_INTERVAL_MS : POINTS_MIN_INTERVAL_MS;
    if (state.loadedVersion >= 0 && mode === state.loadedMode &&
        now - state.lastPointsAt < interval) {
      return;
    }
    state.loadingPoints = true;
    const name = info.name;
    try {
      if (mode === 'mesh') {
        await loadMesh(info);
        return;
      }
      const ply = parsePly(await get(api('points', { map: name }), 'buffer'));
      if (name !== state.selected || state.mode !== mode) return;
      const v = ply.vertex || { count: 0, cols: {} };
      const positions = interleave(v, ['x', 'y', 'z'], Float32Array);
      const colors = interleave(v, ['red', 'green', 'blue'], Uint8Array);
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
      geometry.setAttribute('color', new THREE.BufferAttribute(colors, 3, true));
      geometry.computeBoundingSphere();
      const material = new THREE.PointsMaterial({ size: pointSize(),
                                                  vertexColors: THREE.VertexColors });
      showMapObject(new THREE.Points(geometry, material), info, 'points', v.count, 0);
      updateStatus();
    } catch (e) {
      handleError(e, mode);  // 'points' or 'mesh'
    } finally {
      state.loadingPoints = false;
    }
  }

  // Puts the map's points or mesh (or nothing: null) in the scene as version info.version,
  // records what is loaded and reports it in the body's data attributes (the browser test
  // reads them); the view is framed on the first map with content.
  function showMapObject(object, info, mode, points, faces) {
    clearGroup(mapGroup);
    state.cloud = object;
    if (object) mapGroup.add(object);
    state.loadedVersion = info.version;
    state.loadedMode = mode;
    state.lastPointsAt = performance.now();
    body.dataset.mode = mode;
    body.dataset.points = String(points);
    body.dataset.faces = String(faces);
    body.dataset.version = String(info.version);
    if (object && points + faces > 0) {
      state.bounds = object.geometry.boundingSphere.clone();
      if (!state.fitted) fitView();
    }
  }

  // The mesh: marching cubes on the server, fetched as binary glTF (/viewer/api/mesh.glb) at
  // the level of detail the "mesh detail" choice names and loaded with three.js's GLTFLoader,
  // as a headset or any glTF client would. It is drawn with the file's own material: unlit
  // vertex colours (the colours the cameras saw), both sides (walls are seen from inside rooms
  // and from outside). The file's node turns the map's +Z up to glTF's +Y up; this scene is in
  // map coordinates (the "up" choice orients the view), so that turn is undone. A map over the
  // server's triangle cap answers 413; that version is not asked for again, and the status line
  // says why nothing shows.
  function parseGltf(buffer) {
    return new Promise((resolve, reject) => {
      new THREE.GLTFLoader().parse(buffer, '', resolve,
                                   (e) => reject(e instanceof Error ? e : new Error(String(e))));
    });
  }

  async function fetchGlb(params) {
    const response = await fetch(api('mesh.glb', params), { headers: headers(),
                                                             cache: 'no-store' });
    if (!response.ok) {
      let message = response.statusText;
      try { message = (await response.json()).error || message; } catch (e) { /* not JSON */ }
      throw new HttpError(response.status, message);
    }
    return { buffer: await response.arrayBuffer(), headers: response.headers };
  }

  async function loadMesh(info) {
    const name = info.name;
    const triangles = $('mesh-detail').value;
    let answer;
    try {
      answer = await fetchGlb({ map: name, triangles });
    } catch (e) {
      if (!(e instanceof HttpError) || e.status !== 413) throw e;
      if (name !== state.selected || state.mode !== 'mesh') return;
      showMapObject(null, info, 'mesh', 0, 0);
      setStatus('mesh: ' + e.message + ' (showing nothing; switch to points)', true);
      return;
    }
    const gltf = await parseGltf(answer.buffer);
    if (name !== state.selected || state.mode !== 'mesh') return;
    let mesh = null;
    gltf.scene.traverse((o) => { if (o.isMesh && !mesh) mesh = o; });
    let faces = 0;
    if (mesh) {
      if (mesh.parent) mesh.parent.remove(mesh);
      mesh.position.set(0, 0, 0);
      mesh.quaternion.set(0, 0, 0, 1);  // r111 has no Quaternion.identity()
      mesh.scale.set(1, 1, 1);
      mesh.updateMatrix();
      const g = mesh.geometry;
      faces = (g.index ? g.index.count : g.getAttribute('position').count) / 3;
      g.computeBoundingSphere();
      body.dataset.vertices = String(g.getAttribute('position').count);
      body.dataset.material = mesh.material.type;
      body.dataset.vertexColors = String(Boolean(mesh.material.vertexColors));
    }
    body.dataset.meshFormat = 'glb';
    body.dataset.lodTriangles = triangles;
    body.dataset.fullFaces = answer.headers.get('X-Full-Faces') || '0';
    body.dataset.lodErrorM = answer.headers.get('X-Lod-Error-M') || '0';
    showMapObject(mesh, info, 'mesh', 0, faces);
    updateStatus();
  }

  $('point-size').addEventListener('input', () => {
    if (state.cloud && state.cloud.isPoints) state.cloud.material.size = pointSize();
  });

  // Another level of detail of the same version is fetched at once (the view stays).
  $('mesh-detail').addEventListener('change', () => {
    if (state.mode !== 'mesh') return;
    state.loadedVersion = -1;
    const current = state.maps.find((m) => m.name === state.selected);
    if (current) maybeLoadPoints(current);
  });

  // Points / Mesh: the other form of the same version is fetched at once (the view stays).
  function setMode(mode) {
    if (state.mode === mode) return;
    state.mode = mode;
    const current = state.maps.find((m) => m.name === state.selected);
    if (current) maybeLoadPoints(current);
  }
  for (const id of ['show-points', 'show-mesh']) {
    $(id).addEventListener('change', (e) => { if (e.target.checked) setMode(e.target.value); });
  }

  // ---------------------------------------------------------------------------------------
  // Orientation: which world axis points up. "auto": opposite the cameras' mean y axis (people
  // and robots hold cameras upright), +Z without cameras.
  function upVector() {
    const choice = $('up').value;
    const fixed = { '+z': [0, 0, 1], '-z': [0, 0, -1], '+y': [0, 1, 0], '-y': [0, -1, 0] };
    if (fixed[choice]) return new THREE.Vector3(...fixed[choice]);
    const poses = [];
    const t = state.trajectory;
    if (t) {
      for (const c of t.cameras) if (c.frames > 0) poses.push(c.pose);
      for (const k of t.keyframes) poses.push(k);
    }
    if (poses.length === 0) return new THREE.Vector3(0, 0, 1);
    const up = new THREE.Vector3();
    for (const p of poses) {
      const q = new THREE.Quaternion(p[3], p[4], p[5], p[6]);
      up.add(new THREE.Vector3(0, -1, 0).applyQuaternion(q));
    }
    return up.lengthSq() > 1e-9 ? up.normalize() : new THREE.Vector3(0, 0, 1);
  }

  // What the view frames: the cloud, and the cameras and keyframes (which often stand outside
  // the surfaces they look at).
  function viewBounds() {
    const box = new THREE.Box3();
    if (state.cloud) box.setFromBufferAttribute(state.cloud.geometry.getAttribute('position'));
    const t = state.trajectory;
    if (t) {
      for (const c of t.cameras) {
        for (let i = 0; i + 2 < c.path.length; i += 3) {
          box.expandByPoint(new THREE.Vector3(c.path[i], c.path[i + 1], c.path[i + 2]));
        }
      }
      for (const k of t.keyframes) box.expandByPoint(new THREE.Vector3(k[0], k[1], k[2]));
    }
    return box.isEmpty() ? null : box.getBoundingSphere(new THREE.Sphere());
  }

  function fitView() {
    const bounds = viewBounds();
    if (!bounds) return;
    const up = upVector();
    camera.up.copy(up);
    const center = bounds.center;
    const radius = Math.max(bounds.radius, 0.1);
    // From above and to the side, so floors and walls both show.
    const side = Math.abs(up.z) < 0.9 ? new THREE.Vector3(0, 0, 1) : new THREE.Vector3(1, 0, 0);
    side.sub(up.clone().multiplyScalar(side.dot(up))).normalize();
    const dir = side.multiplyScalar(0.8).add(up.clone().multiplyScalar(0.6)).normalize();
    // The sphere just fills the view's height (slightly less: a box's sphere is loose).
    const distance = 0.9 * radius / Math.sin((camera.fov * Math.PI) / 360);
    camera.position.copy(center).add(dir.multiplyScalar(distance));
    camera.near = radius / 200;
    camera.far = radius * 50;
    camera.updateProjectionMatrix();
    controls.target.copy(center);
    controls.update();
    state.fitted = true;
  }
  $('up').addEventListener('change', fitView);

  // ---------------------------------------------------------------------------------------
  // SLAM cameras and keyframes.
  function cvPoseObject(p) {
    const o = new THREE.Object3D();
    o.position.set(p[0], p[1], p[2]);
    o.quaternion.set(p[3], p[4], p[5], p[6]);
    return o;
  }

  // A camera's frustum in its own (OpenCV) frame: apex at the centre, image plane at +z.
  function frustumGeometry(size) {
    const w = size * 0.66, h = size * 0.5, d = size;
    const c = [[-w, -h, d], [w, -h, d], [w, h, d], [-w, h, d]];
    const v = [];
    for (let i = 0; i < 4; ++i) {
      v.push(0, 0, 0, ...c[i]);
      v.push(...c[i], ...c[(i + 1) % 4]);
    }
    v.push(-w * 0.4, -h, d, 0, -h * 1.6, d, 0, -h * 1.6, d, w * 0.4, -h, d);  // "up" is -y
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(v, 3));
    return g;
  }

  function addPickable(object, pose, label, radius) {
    const sphere = new THREE.Mesh(new THREE.SphereBufferGeometry(radius, 12, 8),
                                  new THREE.MeshBasicMaterial({ visible: false }));
    sphere.userData = { pose, label };
    object.add(sphere);
    state.pickables.push(sphere);
  }

  function drawTrajectory(t) {
    clearGroup(slamGroup);
    state.pickables = [];
    const scale = state.bounds ? Math.max(state.bounds.radius, 0.5) : 1.0;
    const frustum = 0.06 * scale;
    let pathPoints = 0;
    t.cameras.forEach((c, i) => {
      const color = TRACK_COLORS[i % TRACK_COLORS.length];
      const n = c.path.length / 3;
      pathPoints += n;
      if (n >= 2) {
        const g = new THREE.BufferGeometry();
        g.setAttribute('position', new THREE.Float32BufferAttribute(c.path, 3));
        slamGroup.add(new THREE.Line(g, new THREE.LineBasicMaterial({ color })));
        slamGroup.add(new THREE.Points(g.clone(), new THREE.PointsMaterial({
          color, size: 3, sizeAttenuation: false })));
      }
      if (c.frames > 0) {
        const o = cvPoseObject(c.pose);
        o.add(new THREE.LineSegments(frustumGeometry(frustum * 1.6),
                                     new THREE.LineBasicMaterial({ color })));
        // A solid marker at the camera's centre: seen at any zoom.
        o.add(new THREE.Mesh(new THREE.SphereBufferGeometry(frustum * 0.35, 16, 12),
                             new THREE.MeshBasicMaterial({ color })));
        addPickable(o, c.pose, c.label, frustum * 0.8);
        slamGroup.add(o);
      }
    });
    t.keyframes.forEach((k, i) => {
      const o = cvPoseObject(k);
      o.add(new THREE.LineSegments(frustumGeometry(frustum),
                                   new THREE.LineBasicMaterial({ color: KEYFRAME_COLOR })));
      addPickable(o, k, 'keyframe ' + i, frustum * 0.5);
      slamGroup.add(o);
    });
    // Loop closures: an edge between the two keyframes that saw one place.
    const loops = t.loops || [];
    if (loops.length > 0) {
      const v = [];
      for (const [a, b] of loops) {
        const p = t.keyframes[a], q = t.keyframes[b];
        if (p && q) v.push(p[0], p[1], p[2], q[0], q[1], q[2]);
      }
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.Float32BufferAttribute(v, 3));
      slamGroup.add(new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: LOOP_COLOR })));
    }
    body.dataset.loops = String(loops.length);
    body.dataset.cameras = String(t.cameras.filter((c) => c.frames > 0).length);
    body.dataset.pathPoints = String(pathPoints);
    body.dataset.keyframes = String(t.keyframes.length);
  }

  function cameraListItem(c, i) {
    const li = document.createElement('li');
    const swatch = document.createElement('span');
    swatch.className = 'swatch';
    swatch.style.background = '#' + TRACK_COLORS[i % TRACK_COLORS.length].toString(16)
        .padStart(6, '0');
    const text = document.createElement('span');
    const where = c.frames > 0 ? ' (' + c.pose.slice(0, 3).map((x) => x.toFixed(2)).join(', ') +
        ')' : '';
    text.textContent = c.label + ' · ' + c.state.toLowerCase() + ' · ' + c.frames + ' frames' +
        (c.active ? '' : ' · ended') + where;
    li.append(swatch, text);
    if (c.frames > 0) {
      li.style.cursor = 'pointer';
      li.addEventListener('click', () => renderAt(c.pose, c.label));
    }
    return li;
  }

  async function pollTrajectory() {
    const name = state.selected;
    if (name === null || state.loadingTrajectory) return;
    state.loadingTrajectory = true;
    try {
      const t = await get(api('trajectory', { map: name }), 'json');
      if (name !== state.selected) return;
      const first = state.trajectory === null || (state.trajectory.cameras.length === 0 &&
                                                  state.trajectory.keyframes.length === 0);
      state.trajectory = t;
      drawTrajectory(t);
      const list = $('cameras');
      list.textContent = '';
      if (t.cameras.length === 0) {
        const li = document.createElement('li');
        li.className = 'muted';
        li.textContent = 'no SLAM stream';
        list.appendChild(li);
      }
      t.cameras.forEach((c, i) => list.appendChild(cameraListItem(c, i)));
      // The first cameras tell which way is up ("auto"): frame the view again once.
      if (first && (t.cameras.length || t.keyframes.length) && $('up').value === 'auto' &&
          state.bounds) {
        fitView();
      }
      updateStatus();
    } catch (e) {
      handleError(e, 'trajectory');
    } finally {
      state.loadingTrajectory = false;
    }
  }

  function updateStatus() {
    const parts = [];
    if (state.selected !== null) parts.push(state.selected);
    if (state.loadedVersion >= 0) parts.push('version ' + state.loadedVersion);
    if (state.cloud && state.cloud.isPoints) parts.push(body.dataset.points + ' points');
    if (state.cloud && state.cloud.isMesh) {
      const full = Number(body.dataset.fullFaces || 0), faces = Number(body.dataset.faces);
      parts.push(faces + ' triangles' + (full > faces
        ? ' of ' + full + ' (error ' + (1000 * Number(body.dataset.lodErrorM)).toFixed(1) +
          ' mm)' : ''));
    }
    const t = state.trajectory;
    if (t && (t.cameras.length || t.keyframes.length)) {
      parts.push((t.slam_running ? 'SLAM running: ' : 'SLAM: ') + t.cameras.length +
                 ' camera(s), ' + t.keyframes.length + ' keyframes');
    }
    setStatus(parts.join(' · '));
  }

  // ---------------------------------------------------------------------------------------
  // Renders: the map seen from a clicked camera or keyframe, or from this view.
  function poseParam(p) {
    return p.map((x) => x.toPrecision(9)).join(',');
  }

  async function renderAt(pose, label) {
    if (state.selected === null) return;
    const name = state.selected;
    $('render-info').textContent = 'rendering from ' + label + '…';
    $('render-info').className = 'muted small';
    const params = { map: name, pose: poseParam(pose), width: RENDER_WIDTH,
                     height: RENDER_HEIGHT, fov: RENDER_FOV };
    try {
      // One after the other: the server serves two renders at a time.
      const color = await get(api('render', { ...params, image: 'color' }), 'blob');
      const depthResponse = await fetch(api('render', { ...params, image: 'depth' }),
                                        { headers: headers(), cache: 'no-store' });
      if (!depthResponse.ok) throw new HttpError(depthResponse.status, 'depth render failed');
      const range = (depthResponse.headers.get('X-Depth-Range') || '').split(',');
      const depth = await depthResponse.blob();
      for (const [id, blob] of [['render-color', color], ['render-depth', depth]]) {
        const img = $(id);
        if (img.src) URL.revokeObjectURL(img.src);
        img.src = URL.createObjectURL(blob);
      }
      $('depth-caption').textContent = range.length === 2 && parseFloat(range[1]) > 0
          ? 'depth ' + parseFloat(range[0]).toFixed(2) + '–' + parseFloat(range[1]).toFixed(2) +
            ' m (near bright)'
          : 'depth (nothing rendered)';
      $('render-figures').hidden = false;
      $('render-info').textContent = name + ' from ' + label;
      body.dataset.renders = String(parseInt(body.dataset.renders || '0', 10) + 1);
    } catch (e) {
      if (e instanceof HttpError && e.status === 401) showTokenForm();
      $('render-info').textContent = 'render: ' + e.message;
      $('render-info').className = 'error small';
    }
  }

  $('render-view').addEventListener('click', () => {
    const q = camera.quaternion.clone().multiply(CV_TO_GL);
    const p = camera.position;
    renderAt([p.x, p.y, p.z, q.x, q.y, q.z, q.w], 'this view');
  });

  // A click (not a drag) on a camera or keyframe renders from it.
  const raycaster = new THREE.Raycaster();
  let downAt = null;
  renderer.domElement.addEventListener('pointerdown', (e) => { downAt = [e.clientX, e.clientY]; });
  renderer.domElement.addEventListener('pointerup', (e) => {
    if (!downAt || Math.hypot(e.clientX - downAt[0], e.clientY - downAt[1]) > 4) return;
    const rect = renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((e.clientX - rect.left) / rect.width) * 2 - 1,
                                  -((e.clientY - rect.top) / rect.height) * 2 + 1);
    raycaster.setFromCamera(ndc, camera);
    const hits = raycaster.intersectObjects(state.pickables, false);
    if (hits.length) renderAt(hits[0].object.userData.pose, hits[0].object.userData.label);
  });

  // ---------------------------------------------------------------------------------------
  // Start.
  body.dataset.points = '0';
  body.dataset.faces = '0';
  // A reloaded page may keep the radio button it had.
  state.mode = $('show-mesh').checked ? 'mesh' : 'points';
  body.dataset.mode = state.mode;
  body.dataset.cameras = '0';
  body.dataset.pathPoints = '0';
  body.dataset.keyframes = '0';
  animate();
  pollMaps();
  setInterval(pollMaps, MAPS_EVERY_MS);
  setInterval(pollTrajectory, TRAJECTORY_EVERY_MS);
})();
