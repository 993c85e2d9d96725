//! The hot path: a surrogate bound to one weather year ([`Surrogate::bind`]).

use ndarray::{s, Array3, ArrayView2, ArrayView3};
use ort::value::{Tensor, TensorRef};

use super::{
    ort_err, run_on_sessions, split_runs, Result, Runs, Surrogate, SurrogateError, METADATA_FILE,
};

/// A surrogate bound to one weather year ([`Surrogate::bind`]): each evaluation only writes the
/// normalised parameters; the weather part stays in `gw`.
pub struct Evaluator {
    pub(super) surrogate: Surrogate,
    pub(super) xw: Tensor<f32>,
    /// Chunked hourly rows for the fused graph.
    pub(super) xc: Option<Array3<f32>>,
    pub(super) n_hours: usize,
    pub(super) p: Vec<f32>,
    pub(super) out: Array3<f32>,
}

impl Evaluator {
    /// The surrogate (metadata).
    pub fn surrogate(&self) -> &Surrogate {
        &self.surrogate
    }

    /// Releases the surrogate (e.g. to bind another weather year).
    pub fn into_surrogate(self) -> Surrogate {
        self.surrogate
    }

    /// Hours of the bound weather.
    pub fn n_hours(&self) -> usize {
        self.n_hours
    }

    /// One parameter vector (raw values, the surrogate's parameter order) -> `[n_hours,
    /// n_outputs]` kWh, a view of a buffer reused by the next call.
    pub fn evaluate(&mut self, params: &[f64]) -> Result<ArrayView2<'_, f32>> {
        let y = self.evaluate_batch(std::slice::from_ref(&params))?;
        Ok(y.index_axis_move(ndarray::Axis(0), 0))
    }

    /// Several parameter vectors -> `[n_proposals, n_hours, n_outputs]` kWh, a view of a buffer
    /// reused by the next call. Fused graph: the (proposal, chunk) pairs are split into
    /// `threads` contiguous runs, each run on its own single-threaded session on its own thread
    /// (no intra-op synchronisation; every intermediate of a chunk stays in that core's cache).
    /// Without a fused graph: one fast-graph run per proposal.
    pub fn evaluate_batch<P: AsRef<[f64]>>(&mut self, params: &[P]) -> Result<ArrayView3<'_, f32>> {
        let n = params.len();
        if n == 0 {
            return Err(SurrogateError::Input(
                "no parameter vectors to evaluate".into(),
            ));
        }
        let n_out = self.surrogate.meta.outputs.len();
        if self.out.dim().0 != n {
            self.out = Array3::zeros((n, self.n_hours, n_out));
        }
        if self.surrogate.fused.is_some() {
            self.evaluate_fused(params)?;
            return Ok(self.out.slice(s![.., .., ..]));
        }
        let np = self.p.len();
        for (i, p) in params.iter().enumerate() {
            self.surrogate
                .meta
                .normalise_params(p.as_ref(), &mut self.p)?;
            let outputs = self
                .surrogate
                .fast
                .run(ort::inputs![
                    "p" => TensorRef::from_array_view(([1usize, np], &self.p[..])).map_err(ort_err)?,
                    "xw" => &self.xw,
                ])
                .map_err(ort_err)?;
            let y = outputs["y"].try_extract_array::<f32>().map_err(ort_err)?;
            if y.shape() != [1, self.n_hours, n_out] {
                return Err(SurrogateError::Ort(format!(
                    "fast graph returned shape {:?}, expected [1, {}, {n_out}]",
                    y.shape(),
                    self.n_hours
                )));
            }
            let src = y
                .as_slice()
                .ok_or_else(|| SurrogateError::Ort("non-contiguous output".into()))?;
            self.out
                .index_axis_mut(ndarray::Axis(0), i)
                .as_slice_mut()
                .expect("standard layout")
                .copy_from_slice(src);
        }
        Ok(self.out.slice(s![.., .., ..]))
    }

    fn evaluate_fused<P: AsRef<[f64]>>(&mut self, params: &[P]) -> Result<()> {
        let meta = &self.surrogate.meta;
        let np = meta.params.len();
        let mut ps = vec![0f32; params.len() * np];
        for (p, row) in params.iter().zip(ps.chunks_mut(np)) {
            meta.normalise_params(p.as_ref(), row)?;
        }
        let fused = self.surrogate.fused.as_mut().expect("fused graph");
        let xc = self.xc.as_ref().expect("bound with the fused graph");
        let (n_chunks, n_hours, chunk) = (xc.dim().0, self.n_hours, fused.chunk);
        let n_out = self.out.dim().2;
        // Worker w takes the flat (proposal, chunk) items [w * total / workers, ...): contiguous
        // runs of one proposal's chunks, written to disjoint rows of `out`.
        let mut outs: Vec<_> = self
            .out
            .outer_iter_mut()
            .map(|o| Some(o.into_slice().expect("standard layout")))
            .collect();
        let jobs: Vec<Runs<'_>> = split_runs(params.len(), n_chunks, fused.sessions.len())
            .into_iter()
            .map(|runs| {
                runs.into_iter()
                    .map(|(i, c0, c1)| {
                        let rows = (c1 * chunk).min(n_hours) - c0 * chunk;
                        let rest = outs[i].take().expect("disjoint runs");
                        let (mine, tail) = rest.split_at_mut(rows * n_out);
                        outs[i] = Some(tail);
                        (i, c0, c1, mine)
                    })
                    .collect()
            })
            .collect();
        let ps = &ps;
        run_on_sessions(&mut fused.sessions, jobs, |session, runs: Runs<'_>| {
            for (i, c0, c1, dst) in runs {
                let x = xc.slice(s![c0..c1, .., ..]);
                let outputs = session
                    .run(ort::inputs![
                        "p" => TensorRef::from_array_view(([1usize, np], &ps[i * np..(i + 1) * np]))
                            .map_err(ort_err)?,
                        "xw" => TensorRef::from_array_view(x).map_err(ort_err)?,
                    ])
                    .map_err(ort_err)?;
                let y = outputs["y"].try_extract_array::<f32>().map_err(ort_err)?;
                if y.shape() != [c1 - c0, chunk, n_out] {
                    return Err(SurrogateError::Ort(format!(
                        "fused graph returned shape {:?}, expected [{}, {chunk}, {n_out}]",
                        y.shape(),
                        c1 - c0
                    )));
                }
                let src = y
                    .as_slice()
                    .ok_or_else(|| SurrogateError::Ort("non-contiguous output".into()))?;
                dst.copy_from_slice(&src[..dst.len()]);
            }
            Ok(())
        })
        .map(|_| ())
    }

    /// Whether the surrogate has the VJP graph ([`Evaluator::vjp_batch`]).
    pub fn has_gradient(&self) -> bool {
        self.surrogate.vjp.is_some()
    }

    /// Vector-Jacobian products: for each parameter vector `params[i]` (raw values) and its
    /// cotangent `cotangents[i]` (`[n_hours, n_outputs]`, e.g. `d ln L / d y` in 1 / kWh), the
    /// gradient `sum_(t, k) v_tk dy_tk / d theta_j` with respect to the raw parameters. The
    /// (proposal, chunk) pairs are split over the threads as in [`Evaluator::evaluate_batch`]
    /// and the partial sums added. About 2.3 forward evaluations of arithmetic.
    ///
    /// # Errors
    /// Without a VJP graph (surrogates trained before it existed: `python -m bemcal_train
    /// --add-vjp DIR` adds it), or on shape mismatches.
    pub fn vjp_batch<P: AsRef<[f64]>>(
        &mut self,
        params: &[P],
        cotangents: ArrayView3<'_, f32>,
    ) -> Result<Vec<Vec<f64>>> {
        let meta = &self.surrogate.meta;
        let np = meta.params.len();
        let n_out = meta.outputs.len();
        let Some(vjp) = self.surrogate.vjp.as_mut() else {
            return Err(SurrogateError::Metadata {
                path: self.surrogate.dir.join(METADATA_FILE),
                message: "no gradient graph (files.vjp): retrain, or add it with \
                          `python -m bemcal_train --add-vjp DIR`"
                    .into(),
            });
        };
        if cotangents.dim() != (params.len(), self.n_hours, n_out) {
            return Err(SurrogateError::Input(format!(
                "cotangents have shape {:?}, expected [{}, {}, {n_out}]",
                cotangents.dim(),
                params.len(),
                self.n_hours
            )));
        }
        let mut ps = vec![0f32; params.len() * np];
        for (p, row) in params.iter().zip(ps.chunks_mut(np)) {
            meta.normalise_params(p.as_ref(), row)?;
        }
        let xc = self.xc.as_ref().expect("bound with the fused graph");
        let (n_chunks, chunk) = (xc.dim().0, vjp.chunk);
        // Chunked cotangents, zero on the rows past the last hour.
        let mut vc = Array3::<f32>::zeros((params.len() * n_chunks, chunk, n_out));
        for i in 0..params.len() {
            for t in 0..self.n_hours {
                for k in 0..n_out {
                    vc[[i * n_chunks + t / chunk, t % chunk, k]] = cotangents[[i, t, k]];
                }
            }
        }
        let (ps, vc) = (&ps, &vc);
        let jobs = split_runs(params.len(), n_chunks, vjp.sessions.len());
        let parts = run_on_sessions(&mut vjp.sessions, jobs, |session, runs| {
            let mut part = Vec::new();
            for (i, c0, c1) in runs {
                let outputs = session
                    .run(ort::inputs![
                        "p" => TensorRef::from_array_view(([1usize, np], &ps[i * np..(i + 1) * np]))
                            .map_err(ort_err)?,
                        "xw" => TensorRef::from_array_view(xc.slice(s![c0..c1, .., ..])).map_err(ort_err)?,
                        "v" => TensorRef::from_array_view(
                            vc.slice(s![i * n_chunks + c0..i * n_chunks + c1, .., ..])
                        ).map_err(ort_err)?,
                    ])
                    .map_err(ort_err)?;
                let g = outputs["g"].try_extract_array::<f32>().map_err(ort_err)?;
                if g.shape() != [1, np] {
                    return Err(SurrogateError::Ort(format!(
                        "gradient graph returned shape {:?}, expected [1, {np}]",
                        g.shape()
                    )));
                }
                part.push((i, g.iter().map(|&v| f64::from(v)).collect::<Vec<f64>>()));
            }
            Ok(part)
        })?;
        // d p_norm / d theta = 1 / (max - min).
        let mut grads = vec![vec![0.0; np]; params.len()];
        for (i, g) in parts.into_iter().flatten() {
            for ((o, v), spec) in grads[i].iter_mut().zip(g).zip(&meta.params) {
                *o += v / (spec.max - spec.min);
            }
        }
        Ok(grads)
    }
}
