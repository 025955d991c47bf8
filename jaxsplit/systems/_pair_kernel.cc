// The colour flow of the pair fast path (_spin_pairs.py) as one CPU loop: XLA's CPU emitter
// forms no multi-output fusion, so its kernel evaluated a pair's sum, |s|^2, polynomials and
// cross products once per new component (six times a pair). Here they are evaluated once.
//
// x: (..., 3, L_1, ..., L_d), components first, row-major; the colour pairs sites 2k + parity
// and 2k + parity + 1 (mod L) along `axis`. For a bond H = -J S_i.S_j, with k = J t / 2,
// s = a + b, z = k^2 |s|^2 = phi^2, c = cos phi, q = sin phi / phi:
//   a' = a - 2 (A s x a - B s x (s x a)),  A = k q c,  B = k^2 q^2,   b' = s - a'
// c and q by the polynomials in z that the Python side passes (economized to a quarter of the
// dtype's epsilon on the first tier's range) where its tier test chose them (tier 0, for every
// J t of a batch), else by the C library's sin and cos.
// jt (J t) has one value per leading batch block (a vmap of h or J adds leading axes).
// One thread: it nearly saturates the memory bandwidth at 10^6 spins, and splitting the work over
// XLA's intra-op threads (ffi::ThreadPool, a spin-wait for the pieces) measured slower: 27 against
// 36 M spin-steps/s at 100^3, 23 against 42 at 32^3 (Strang, 2 cores, 2026-11-28).
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

template <int N, typename T>
inline T Horner(const T* coefficients, T z) {
  T acc = coefficients[N - 1];
  for (int p = N - 2; p >= 0; --p) acc = acc * z + coefficients[p];
  return acc;
}

// `count` pairs, a at a0 + j*kStride and b at b0 + j*kStride in each component (in place or not:
// a pair is read before it is written). NC, NS: the polynomials' terms; NC == 0: the C library.
template <typename T, int kStride, int NC, int NS>
void Pairs(const T* const in[3], T* const out[3], std::int64_t a0, std::int64_t b0, std::int64_t count, T k,
           const T* cos_c, const T* sin_c) {
  const T k2 = k * k;
  // in and out may be the same buffer: each pair is read before it is written and pairs are
  // disjoint, so vectors of pairs may be loaded, turned and stored (ivdep: no dependence)
#pragma GCC ivdep
  for (std::int64_t j = 0; j < count; ++j) {
    const std::int64_t ia = a0 + j * kStride, ib = b0 + j * kStride;
    const T a0_ = in[0][ia], a1 = in[1][ia], a2 = in[2][ia];
    const T s0 = a0_ + in[0][ib], s1 = a1 + in[1][ib], s2 = a2 + in[2][ib];
    const T z = k2 * (s0 * s0 + s1 * s1 + s2 * s2);
    T c, q;
    if constexpr (NC > 0) {
      c = Horner<NC>(cos_c, z);
      q = Horner<NS>(sin_c, z);
    } else {
      const T phi = std::sqrt(z);
      c = std::cos(phi);
      q = phi > 0 ? std::sin(phi) / phi : T(1);
    }
    const T A = k * (q * c), B = k2 * (q * q);
    const T u0 = s1 * a2 - s2 * a1, u1 = s2 * a0_ - s0 * a2, u2 = s0 * a1 - s1 * a0_;
    const T w0 = s1 * u2 - s2 * u1, w1 = s2 * u0 - s0 * u2, w2 = s0 * u1 - s1 * u0;
    const T n0 = a0_ - 2 * (A * u0 - B * w0), n1 = a1 - 2 * (A * u1 - B * w1), n2 = a2 - 2 * (A * u2 - B * w2);
    out[0][ia] = n0;
    out[1][ia] = n1;
    out[2][ia] = n2;
    out[0][ib] = s0 - n0;
    out[1][ib] = s1 - n1;
    out[2][ib] = s2 - n2;
  }
}

template <typename T>
struct Flow {
  const T* src;
  T* dst;
  const T* jt;
  const T* cos_c;
  const T* sin_c;
  std::int64_t sites, outer, length, inner, parity, per_jt, rows;

  // rows: (batch, outer, pair p along the axis) of `inner` contiguous pairs, or along the last
  // axis (inner == 1) (batch, outer) of interleaved pairs
  template <int NC, int NS>
  void Row(std::int64_t row) const {
    std::int64_t b, o, p = 0;
    if (inner > 1) {
      p = row % (length / 2);
      o = (row / (length / 2)) % outer;
      b = row / (length / 2) / outer;
    } else {
      o = row % outer;
      b = row / outer;
    }
    const T k = jt[b / per_jt] / 2;
    const T* in[3];
    T* out[3];
    for (int c = 0; c < 3; ++c) {
      in[c] = src + (b * 3 + c) * sites;
      out[c] = dst + (b * 3 + c) * sites;
    }
    const std::int64_t base = o * length * inner;
    if (inner > 1) {  // a row of `inner` contiguous pairs: planes i0 and i1 along the axis
      const std::int64_t i0 = 2 * p + parity, i1 = (i0 + 1) % length;
      Pairs<T, 1, NC, NS>(in, out, base + i0 * inner, base + i1 * inner, inner, k, cos_c, sin_c);
    } else {  // along the last axis: pairs interleaved; with parity 1 the last one wraps around
      Pairs<T, 2, NC, NS>(in, out, base + parity, base + parity + 1, length / 2 - parity, k, cos_c, sin_c);
      if (parity) Pairs<T, 1, NC, NS>(in, out, base + length - 1, base, 1, k, cos_c, sin_c);
    }
  }
};

template <typename T, int NC, int NS>
void Run(const Flow<T>& flow) {
  for (std::int64_t row = 0; row < flow.rows; ++row) flow.template Row<NC, NS>(row);
}

template <typename T>
ffi::Error Typed(ffi::AnyBuffer x, ffi::AnyBuffer jt, ffi::AnyBuffer tier,
                 ffi::AnyBuffer cos_c, ffi::AnyBuffer sin_c, ffi::Result<ffi::AnyBuffer> y, std::int64_t d,
                 std::int64_t axis, std::int64_t parity) {
  const auto dims = x.dimensions();
  const std::int64_t rank = static_cast<std::int64_t>(dims.size());
  if (d < 1 || rank < d + 1 || axis < 0 || axis >= d || dims[rank - d - 1] != 3 || (parity != 0 && parity != 1))
    return ffi::Error::InvalidArgument("jaxsplit pair flow: state is not (..., 3, L_1, ..., L_d)");
  Flow<T> flow{x.typed_data<T>(), y->typed_data<T>(), jt.typed_data<T>(), cos_c.typed_data<T>(),
               sin_c.typed_data<T>()};
  std::int64_t batch = 1;
  for (std::int64_t i = 0; i < rank - d - 1; ++i) batch *= dims[i];
  flow.sites = flow.outer = flow.inner = 1;
  for (std::int64_t i = 0; i < d; ++i) {
    const std::int64_t extent = dims[rank - d + i];
    flow.sites *= extent;
    if (i < axis) flow.outer *= extent;
    if (i > axis) flow.inner *= extent;
  }
  flow.length = dims[rank - d + axis];
  flow.parity = parity;
  if (flow.length % 2 != 0 || flow.length < 2)
    return ffi::Error::InvalidArgument("jaxsplit pair flow: an odd length along the axis");
  const std::int64_t n_jt = static_cast<std::int64_t>(jt.element_count());
  if (n_jt < 1 || batch % n_jt != 0 || static_cast<std::int64_t>(tier.element_count()) != n_jt)
    return ffi::Error::InvalidArgument("jaxsplit pair flow: J t does not match the batch");
  flow.per_jt = batch / n_jt;
  flow.rows = flow.inner > 1 ? batch * flow.outer * (flow.length / 2) : batch * flow.outer;
  bool polynomial = true;
  const std::int32_t* tiers = tier.typed_data<std::int32_t>();
  for (std::int64_t i = 0; i < n_jt; ++i) polynomial = polynomial && tiers[i] == 0;
  // a vmap broadcasts the coefficients too: their first row is enough
  const std::int64_t n_cos = cos_c.dimensions().back(), n_sin = sin_c.dimensions().back();
  if (!polynomial) {
    Run<T, 0, 0>(flow);
  } else if (n_cos == 10 && n_sin == 9) {
    Run<T, 10, 9>(flow);
  } else if (n_cos == 6 && n_sin == 6) {
    Run<T, 6, 6>(flow);
  } else {
    return ffi::Error::InvalidArgument("jaxsplit pair flow: polynomials of an unexpected degree");
  }
  return ffi::Error::Success();
}

ffi::Error Dispatch(ffi::AnyBuffer x, ffi::AnyBuffer jt, ffi::AnyBuffer tier,
                    ffi::AnyBuffer cos_c, ffi::AnyBuffer sin_c, ffi::Result<ffi::AnyBuffer> y, std::int64_t d,
                    std::int64_t axis, std::int64_t parity) {
  const auto type = x.element_type();
  for (const auto other : {jt.element_type(), cos_c.element_type(), sin_c.element_type(), y->element_type()})
    if (other != type) return ffi::Error::InvalidArgument("jaxsplit pair flow: mixed dtypes");
  if (tier.element_type() != ffi::DataType::S32) return ffi::Error::InvalidArgument("jaxsplit pair flow: tier not int32");
  switch (type) {
    case ffi::DataType::F64:
      return Typed<double>(x, jt, tier, cos_c, sin_c, y, d, axis, parity);
    case ffi::DataType::F32:
      return Typed<float>(x, jt, tier, cos_c, sin_c, y, d, axis, parity);
    default:
      return ffi::Error::InvalidArgument("jaxsplit pair flow: float32 or float64 only");
  }
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(JaxsplitPairFlow, Dispatch,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Ret<ffi::AnyBuffer>()
                                  .Attr<std::int64_t>("d")
                                  .Attr<std::int64_t>("axis")
                                  .Attr<std::int64_t>("parity"));
