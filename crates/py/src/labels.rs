//! The `LabelBricks` class: a label grid built from its z-planes pushed in order and stored by bricks (the core's
//! `LabelBricksBuilder`), for `Medium.labels`, so that a printer-resolution volume is never held as one byte per
//! voxel. The GIL is released while planes are bricked.

use inkopt_core::transport::label_bricks::{LabelBricks as CoreBricks, LabelBricksBuilder};
use numpy::{PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::arrays::{c_slice, err};

/// LabelBricks(shape_zyx): push(planes) the grid's z-planes in order ((K, Y, X) uint8, any K at a time); once
/// every plane is pushed, `Medium.labels` takes the bricks (a scene built from that medium holds them; this object
/// is then spent).
#[pyclass(module = "inkopt._core")]
pub(crate) struct LabelBricks {
    shape: [usize; 3],
    builder: Option<LabelBricksBuilder>,
}

#[pymethods]
impl LabelBricks {
    #[new]
    fn new(shape: (usize, usize, usize)) -> PyResult<Self> {
        let (nz, ny, nx) = shape;
        let builder = LabelBricksBuilder::new([nx, ny, nz]).map_err(err)?;
        Ok(LabelBricks { shape: [nz, ny, nx], builder: Some(builder) })
    }

    /// push(planes): the next z-planes, (K, Y, X) uint8 C-contiguous (255: empty); a ValueError, nothing taken,
    /// for planes of another (Y, X) or more than are left.
    fn push(&mut self, py: Python<'_>, planes: PyReadonlyArray3<u8>) -> PyResult<()> {
        let s = planes.shape();
        if s[1..] != self.shape[1..] {
            return Err(err(format!("planes of shape {s:?} for a grid of (Y, X) = {:?}", &self.shape[1..])));
        }
        let values = c_slice(&planes, "planes")?;
        let b = self.builder.as_mut().ok_or_else(|| err("these label bricks were already taken by a medium"))?;
        py.detach(|| b.push(values)).map_err(err)
    }

    /// Planes not pushed yet.
    #[getter]
    fn planes_left(&self) -> usize {
        self.builder.as_ref().map_or(0, |b| b.planes_left())
    }

    /// The grid's shape (Z, Y, X).
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        (self.shape[0], self.shape[1], self.shape[2])
    }
}

impl LabelBricks {
    /// The finished bricks, taken (this object is spent); a ValueError if planes are missing or they were taken.
    pub(crate) fn take(&mut self, py: Python<'_>, shape: [usize; 3]) -> PyResult<CoreBricks> {
        if shape != self.shape {
            return Err(err(format!("label bricks of shape {:?} for a grid of {shape:?}", self.shape)));
        }
        let b = self.builder.take().ok_or_else(|| err("these label bricks were already taken by a medium"))?;
        if b.planes_left() > 0 {
            let left = b.planes_left();
            self.builder = Some(b);
            return Err(err(format!("{left} of {} planes of the label bricks were not pushed", self.shape[0])));
        }
        py.detach(|| b.finish()).map_err(err)
    }
}
