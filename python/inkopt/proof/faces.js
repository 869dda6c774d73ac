// The soft-proof page's slab faces: for every textured face, two results stacked with a swipe line between them
// (the left one shown left of the line), and the ΔE76 heat maps. Each face is shown `zoom` times its texel
// picture's width (set here: the page's policy allows no style attributes). A spectral run's page has a light
// selector (#light, valued by the light's index): a face's pictures under light i > 0 are in face.by_light[i].
(function () {
  const D = JSON.parse(document.getElementById('inkopt-data').textContent);
  const light = document.getElementById('light');
  for (const face of (D.slab ? D.slab.faces : [])) {
    const root = document.getElementById('face-' + face.name);
    root.style.setProperty('--w', face.width * D.slab.zoom + 'px');
    const [a, b] = root.querySelectorAll('img.layer');
    const [pa, pb] = root.querySelectorAll('select');
    const heat = root.querySelector('input[type=checkbox]');
    const swipe = root.querySelector('input[type=range]');
    const line = root.querySelector('.line');
    const under = (what, key) => {
      const i = light ? Number(light.value) : 0;
      const set = i > 0 && Array.isArray(face.by_light) ? face.by_light[i] : null;
      return (set && set[what] && set[what][key]) || face[what][key];
    };
    const src = (key) => (heat.checked && under('heat', key)) || under('pictures', key);
    const draw = () => {
      a.src = src(pa.value);
      b.src = src(pb.value);
      b.style.clipPath = `inset(0 0 0 ${swipe.value}%)`;
      line.style.left = swipe.value + '%';
      root.dataset.view = (heat.checked ? 'heat:' : '') + pa.value + '|' + pb.value;
      root.dataset.light = light ? light.value : '0';
    };
    for (const el of [pa, pb, heat, swipe, light]) if (el) el.addEventListener('input', draw);
    draw();
  }
})();
