// The soft-proof page's light selector (a spectral run's): shows the figures table of the chosen light (each table
// marked with its light's index in data-light-table) and hides the others; the pictures and the 3D view switch in
// faces.js and viewer3d.js. The body's data-light attribute says which light is shown.
(function () {
  const light = document.getElementById('light');
  if (!light) return;
  const show = () => {
    for (const el of document.querySelectorAll('[data-light-table]')) el.hidden = el.dataset.lightTable !== light.value;
    document.body.dataset.light = light.value;
  };
  light.addEventListener('input', show);
  show();
})();
