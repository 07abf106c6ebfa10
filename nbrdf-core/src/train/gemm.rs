//! A register-blocked micro matrix product for the tiny matrices of NBRDF training.
//!
//! Every product of the forward and backward passes has the form
//! `C[i][j] = init + sum_k A(i, k) B[k][j]` with `B` and `C` row-major and `A` read through
//! arbitrary strides (so `A` or its transpose can be used without copying). Rows of `C` are
//! computed in blocks of up to 3, columns in blocks of up to 24 (3 vectors of 8): 9 accumulators
//! stay in registers while each step of `k` loads one row of `B` and broadcasts 3 elements of `A`.
//! The sum over `k` runs in order, so results do not depend on how rows are grouped.

use crate::fastmath::MulAdd;

/// Width of one column block: the `f32` lanes of an AVX register.
pub const VEC: usize = 8;

/// A read-only strided view `A(i, k) = data[i * row_stride + k * col_stride]`.
#[derive(Clone, Copy)]
pub struct Strided<'a> {
    pub data: &'a [f32],
    pub row_stride: usize,
    pub col_stride: usize,
}

/// What `C` starts from before the products are added.
#[derive(Clone, Copy)]
pub enum Init<'a> {
    Zero,
    /// Every row starts as this row (a bias).
    Row(&'a [f32]),
}

/// What is applied to a block of `C` before it is stored.
#[derive(Clone, Copy)]
pub enum Post<'a> {
    None,
    /// `max(c, 0)`.
    Relu,
    /// `c` where the same element of this matrix (same shape and stride as `C`) is positive,
    /// else 0: the relu derivative applied to a back-propagated gradient.
    MaskPositive(&'a [f32]),
}

/// `C[i][j] = post(init + sum_{k < depth} A(i, k) B[k][j])` for `i < rows` and `j < cols`, where
/// `cols` is a multiple of [`VEC`], `B` has row stride `ldb` and `C` row stride `ldc`.
/// With `M = Fused` it runs AVX2 and FMA instructions: only the kernels compiled for and
/// dispatched to those features call it so (`mlp_grad`'s `*_avx2`), which is why this module is
/// private to the crate.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn gemm<M: MulAdd>(
    rows: usize,
    cols: usize,
    depth: usize,
    a: Strided<'_>,
    b: &[f32],
    ldb: usize,
    c: &mut [f32],
    ldc: usize,
    init: Init<'_>,
    post: Post<'_>,
) {
    debug_assert!(cols % VEC == 0);
    let mut j0 = 0;
    while j0 < cols {
        let left = (cols - j0) / VEC;
        let step = match left {
            1 => block_rows::<M, 1>(rows, depth, a, b, ldb, c, ldc, init, post, j0),
            2 => block_rows::<M, 2>(rows, depth, a, b, ldb, c, ldc, init, post, j0),
            _ => block_rows::<M, 3>(rows, depth, a, b, ldb, c, ldc, init, post, j0),
        };
        j0 += step;
    }
}

/// All rows for the column block starting at `j0` of `NB` vectors; returns the block width.
/// A block holds at most 8, 6 or 3 rows (8, 12 or 9 accumulators of the 16 vector registers), and
/// the rows are split into blocks of near-equal height (21 rows: 7 + 7 + 7, or 3 x 7) rather than
/// full blocks and a remainder: a block of one or two rows has too few independent accumulators
/// to hide the latency of the multiply-adds, and with the 64-deep sums of the weight gradients
/// such a remainder cost as much as a full block. Four rows of three vectors (12 accumulators,
/// 3 rows of `B` and a broadcast) needed all 16 registers and spilled, so three vectors take at
/// most 3 rows (docs/results/training.md).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn block_rows<M: MulAdd, const NB: usize>(
    rows: usize,
    depth: usize,
    a: Strided<'_>,
    b: &[f32],
    ldb: usize,
    c: &mut [f32],
    ldc: usize,
    init: Init<'_>,
    post: Post<'_>,
    j0: usize,
) -> usize {
    let tallest = match NB {
        1 => 8,
        2 => 6,
        _ => 3,
    };
    let mut i0 = 0;
    while i0 < rows {
        let left = rows - i0;
        let height = left.div_ceil(left.div_ceil(tallest));
        // `height <= tallest`, so the last arm is the tallest block.
        macro_rules! run {
            ($($mr:literal)* ; $last:literal) => {
                match height {
                    $($mr => block::<M, $mr, NB>(i0, j0, depth, a, b, ldb, c, ldc, init, post),)*
                    _ => block::<M, $last, NB>(i0, j0, depth, a, b, ldb, c, ldc, init, post),
                }
            };
        }
        match NB {
            1 => run!(1 2 3 4 5 6 7; 8),
            2 => run!(1 2 3 4 5; 6),
            _ => run!(1 2 3; 4),
        }
        i0 += height;
    }
    NB * VEC
}

/// `out[j] = sum_k b[k][j]` for `j < cols` (a multiple of [`VEC`]), summing rows in four
/// interleaved partial sums (fixed order, so deterministic) to hide the add latency.
#[inline(always)]
pub fn column_sums(depth: usize, cols: usize, b: &[f32], ldb: usize, out: &mut [f32]) {
    for j0 in (0..cols).step_by(VEC) {
        let mut acc = [[0.0f32; VEC]; 4];
        let mut k = 0;
        while k + 4 <= depth {
            for (p, acc_p) in acc.iter_mut().enumerate() {
                let row = &b[(k + p) * ldb + j0..(k + p) * ldb + j0 + VEC];
                for q in 0..VEC {
                    acc_p[q] += row[q];
                }
            }
            k += 4;
        }
        while k < depth {
            let row = &b[k * ldb + j0..k * ldb + j0 + VEC];
            for q in 0..VEC {
                acc[0][q] += row[q];
            }
            k += 1;
        }
        for q in 0..VEC {
            out[j0 + q] = (acc[0][q] + acc[1][q]) + (acc[2][q] + acc[3][q]);
        }
    }
}

/// One `MR x (NB * 8)` block of `C` held in registers.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn block<M: MulAdd, const MR: usize, const NB: usize>(
    i0: usize,
    j0: usize,
    depth: usize,
    a: Strided<'_>,
    b: &[f32],
    ldb: usize,
    c: &mut [f32],
    ldc: usize,
    init: Init<'_>,
    post: Post<'_>,
) {
    let acc = accumulate::<M, MR, NB>(i0, j0, depth, a, b, ldb, init);
    for (r, acc_r) in acc.iter().enumerate() {
        let at = (i0 + r) * ldc + j0;
        for (nb, &acc_v) in acc_r.iter().enumerate() {
            let mut v = M::to_array8(acc_v);
            match post {
                Post::None => {}
                Post::Relu => v.iter_mut().for_each(|v| *v = v.max(0.0)),
                Post::MaskPositive(m) => {
                    let m_v = &m[at + nb * VEC..at + (nb + 1) * VEC];
                    for q in 0..VEC {
                        v[q] = keep_where_positive(v[q], m_v[q]);
                    }
                }
            }
            c[at + nb * VEC..at + (nb + 1) * VEC].copy_from_slice(&v);
        }
    }
}

/// `init + sum_k A(i, k) B[k][j]` of one block, its `MR * NB` accumulators whole vectors
/// ([`MulAdd::V8`]). Written lane by lane, the accumulators were an array in memory that the
/// compiler stored back on every step of `k` (one store per multiply-add, perf on Zen 3), and
/// every read had a bounds check inside the loop.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn accumulate<M: MulAdd, const MR: usize, const NB: usize>(
    i0: usize,
    j0: usize,
    depth: usize,
    a: Strided<'_>,
    b: &[f32],
    ldb: usize,
    init: Init<'_>,
) -> [[M::V8; NB]; MR] {
    // (Plain loops, not `std::array::from_fn`: its closure was left as a call inside the loop.)
    // SAFETY: here and at every `M::` eight-lane operation below, the CPU features of `Fused`
    // hold: `gemm` is called with it only from code dispatched to them.
    let mut start = [unsafe { M::splat8(0.0) }; NB];
    if let Init::Row(row) = init {
        let row = &row[j0..j0 + NB * VEC];
        for (nb, v) in start.iter_mut().enumerate() {
            // SAFETY: `row` holds `NB * VEC` floats.
            *v = unsafe { M::load8(row.as_ptr().add(nb * VEC)) };
        }
    }
    let mut acc = [start; MR];
    if depth == 0 {
        return acc;
    }
    // Every index the loop reads, checked once.
    assert!((i0 + MR - 1) * a.row_stride + (depth - 1) * a.col_stride < a.data.len());
    assert!((depth - 1) * ldb + j0 + NB * VEC <= b.len());
    for k in 0..depth {
        // SAFETY: the CPU, as above.
        let mut b_k = [unsafe { M::splat8(0.0) }; NB];
        for (nb, v) in b_k.iter_mut().enumerate() {
            // SAFETY: `k < depth` and `nb < NB`: inside the second bound asserted above.
            *v = unsafe { M::load8(b.as_ptr().add(k * ldb + j0 + nb * VEC)) };
        }
        for (r, acc_r) in acc.iter_mut().enumerate() {
            // SAFETY: `r < MR` and `k < depth`: inside the first bound asserted above.
            let a_ik = unsafe {
                *a.data
                    .get_unchecked((i0 + r) * a.row_stride + k * a.col_stride)
            };
            // SAFETY: the CPU, as above.
            let a_ik = unsafe { M::splat8(a_ik) };
            for (acc_v, &b_v) in acc_r.iter_mut().zip(&b_k) {
                // SAFETY: the CPU, as above.
                *acc_v = unsafe { M::mul_add8(a_ik, b_v, *acc_v) };
            }
        }
    }
    acc
}

/// `v` where `m > 0`, else `+0.0`: the same values as `if m > 0.0 { v } else { 0.0 }`, but
/// through a bit mask. Which relu units are active is random, so the branch the select compiled
/// to was mispredicted about half the time and cost a third of the gradient kernel (perf, Zen 3);
/// the mask vectorises.
#[inline(always)]
fn keep_where_positive(v: f32, m: f32) -> f32 {
    let keep = 0u32.wrapping_sub(u32::from(m > 0.0));
    f32::from_bits(v.to_bits() & keep)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fastmath::Unfused;

    #[test]
    fn matches_naive_product_with_strides_and_bias() {
        let (rows, cols, depth) = (7, 40, 5);
        // A stored transposed: A(i, k) = at[k * rows + i].
        let at: Vec<f32> = (0..rows * depth).map(|v| (v as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..depth * cols).map(|v| (v as f32 * 0.11).cos()).collect();
        let bias: Vec<f32> = (0..cols).map(|v| v as f32 * 0.01).collect();
        let mut c = vec![0.0; rows * cols];
        let a = Strided {
            data: &at,
            row_stride: 1,
            col_stride: rows,
        };
        gemm::<Unfused>(
            rows,
            cols,
            depth,
            a,
            &b,
            cols,
            &mut c,
            cols,
            Init::Row(&bias),
            Post::Relu,
        );
        for i in 0..rows {
            for j in 0..cols {
                let expect: f32 = bias[j]
                    + (0..depth)
                        .map(|k| at[k * rows + i] * b[k * cols + j])
                        .sum::<f32>();
                assert!(
                    (c[i * cols + j] - expect.max(0.0)).abs() < 1e-5,
                    "({i}, {j})"
                );
            }
        }
    }

    /// Every block height of every column width: bit for bit the naive sum over `k` in order
    /// (the blocking must not change a single rounding).
    #[test]
    fn every_row_split_is_the_in_order_sum() {
        let depth = 9;
        for cols in [8, 16, 24, 40] {
            for rows in 1..=26 {
                let a: Vec<f32> = (0..rows * depth).map(|v| (v as f32 * 0.71).sin()).collect();
                let b: Vec<f32> = (0..depth * cols).map(|v| (v as f32 * 0.23).cos()).collect();
                let mut c = vec![f32::NAN; rows * cols];
                let view = Strided {
                    data: &a,
                    row_stride: depth,
                    col_stride: 1,
                };
                gemm::<Unfused>(
                    rows,
                    cols,
                    depth,
                    view,
                    &b,
                    cols,
                    &mut c,
                    cols,
                    Init::Zero,
                    Post::None,
                );
                for i in 0..rows {
                    for j in 0..cols {
                        let mut expect = 0.0f32;
                        for k in 0..depth {
                            expect += a[i * depth + k] * b[k * cols + j];
                        }
                        assert_eq!(c[i * cols + j].to_bits(), expect.to_bits(), "{rows}x{cols}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_mask_is_the_select_bit_for_bit() {
        let values = [
            1.5f32,
            -2.0,
            0.0,
            -0.0,
            f32::MIN_POSITIVE,
            f32::INFINITY,
            f32::NAN,
        ];
        for &v in &values {
            for &m in &[1.0f32, 0.0, -0.0, -1.0, f32::MIN_POSITIVE, f32::NAN] {
                let select = if m > 0.0 { v } else { 0.0 };
                assert_eq!(
                    keep_where_positive(v, m).to_bits(),
                    select.to_bits(),
                    "{v} {m}"
                );
            }
        }
    }

    #[test]
    fn column_sums_add_rows() {
        let (depth, cols) = (7, 16);
        let b: Vec<f32> = (0..depth * cols).map(|v| v as f32).collect();
        let mut out = vec![0.0; cols];
        column_sums(depth, cols, &b, cols, &mut out);
        for j in 0..cols {
            assert_eq!(out[j], (0..depth).map(|k| b[k * cols + j]).sum::<f32>());
        }
    }
}
