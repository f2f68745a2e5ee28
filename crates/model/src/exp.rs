//! `exp` of four doubles at once, on the AVX2 and FMA units where the CPU
//! has them: the stepping kernel's exponentials, four wheels' at a time.
//!
//! The algorithm and its constants are those of Arm's optimized-routines
//! (`math/exp.c`, `math/exp_data.c`, by Szabolcs Nagy; MIT OR Apache-2.0
//! WITH LLVM-exception), which glibc has used for `exp` since 2.28:
//! `x = k ln2/128 + r`, `exp(x) = 2^(k/128) exp(r)`, `2^(k/128)` from a
//! 128-entry table of (tail, bits) pairs and `exp(r)` a polynomial of
//! degree 5. The operations run in the order, and with the fused
//! multiply-adds, of glibc's FMA build (`__exp_fma` on x86-64, read from its
//! disassembly), so with glibc on an FMA CPU every lane is bit for bit what
//! [`f64::exp`] gives (tests/exp.rs checks tens of millions of arguments).
//! Lanes outside `2^-54 <= |x| < 512` (tiny, huge, infinite, NaN: glibc's
//! special cases) are computed by `f64::exp`; so is every lane on a CPU
//! without AVX2 and FMA. On another C library `f64::exp` may differ from
//! this in the last bit (both are within an ulp of the true value).

/// `exp` of each lane, chosen at run time: the vector code where the CPU
/// has AVX2 and FMA, else `f64::exp` lane by lane.
#[inline]
pub fn exp4(x: [f64; 4]) -> [f64; 4] {
    #[cfg(target_arch = "x86_64")]
    {
        if exp4_is_vectorised() {
            // SAFETY: the CPU has the features `exp4_fma` is compiled for.
            return unsafe { exp4_fma(x) };
        }
    }
    x.map(f64::exp)
}

/// Whether [`exp4`] runs on the vector units here (else it is `f64::exp`
/// lane by lane).
#[inline]
pub fn exp4_is_vectorised() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn exp4_fma(x: [f64; 4]) -> [f64; 4] {
    // SAFETY: compiled for, and called only on, a CPU with AVX2 and FMA.
    unsafe { exp4_inline(x) }
}

const INV_LN2_N: f64 = f64::from_bits(0x4067_1547_652b_82fe);
const NEG_LN2_HI_N: f64 = f64::from_bits(0xbf76_2e42_fefa_0000);
const NEG_LN2_LO_N: f64 = f64::from_bits(0xbd0c_f79a_bc9e_3b3a);
const C2: f64 = f64::from_bits(0x3fdf_ffff_ffff_fdbd);
const C3: f64 = f64::from_bits(0x3fc5_5555_5555_543c);
const C4: f64 = f64::from_bits(0x3fa5_5555_cf17_2b91);
const C5: f64 = f64::from_bits(0x3f81_1111_67a4_d017);
const SHIFT: f64 = f64::from_bits(0x4338_0000_0000_0000);
/// `top12(2^-54)`: below it `exp(x)` rounds to `1 + x`.
const TOP_TINY: u64 = 0x3c9;
/// `top12(512) - top12(2^-54)`: from 512 on the scale needs care.
const TOP_SPAN: u64 = 0x3f;

#[cfg(target_arch = "x86_64")]
/// The vector code of [`exp4`], to be inlined into a caller compiled for
/// AVX2 and FMA (`#[target_feature(enable = "avx2,fma")]`), where the four
/// arguments and results stay in a register.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[inline(always)]
pub unsafe fn exp4_inline(x: [f64; 4]) -> [f64; 4] {
    use std::arch::x86_64::*;
    let mut out = [0.0; 4];
    _mm256_storeu_pd(out.as_mut_ptr(), exp4_register(_mm256_loadu_pd(x.as_ptr())));
    out
}

#[cfg(target_arch = "x86_64")]
/// [`exp4_inline`] on a register: the same operations, for a caller that
/// keeps its four lanes in registers from one contact to the next.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[inline(always)]
pub unsafe fn exp4_register(xv: std::arch::x86_64::__m256d) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    // kd = round(x 128 / ln2) by the shift trick; ki its integer bits.
    let kd = _mm256_fmadd_pd(xv, _mm256_set1_pd(INV_LN2_N), _mm256_set1_pd(SHIFT));
    let ki = _mm256_castpd_si256(kd);
    let kd = _mm256_sub_pd(kd, _mm256_set1_pd(SHIFT));
    // r = x - kd ln2/128, in two parts.
    let r = _mm256_fmadd_pd(kd, _mm256_set1_pd(NEG_LN2_HI_N), xv);
    let r = _mm256_fmadd_pd(kd, _mm256_set1_pd(NEG_LN2_LO_N), r);
    // The table pair of k mod 128; the exponent k / 128 goes to the top.
    // Each lane's (tail, bits) pair is one 16-byte load, and two unpacks
    // sort the four pairs into tails and bits (no gather: AMD's are slow).
    let mut k = [0u64; 4];
    _mm256_storeu_si256(k.as_mut_ptr().cast(), ki);
    let pair = |j: usize| table_pair(k[j]);
    // [tail0, bits0 | tail2, bits2] and [tail1, bits1 | tail3, bits3].
    let even = _mm256_inserti128_si256::<1>(_mm256_castsi128_si256(pair(0)), pair(2));
    let odd = _mm256_inserti128_si256::<1>(_mm256_castsi128_si256(pair(1)), pair(3));
    let top = _mm256_slli_epi64::<45>(ki);
    let tail = _mm256_castsi256_pd(_mm256_unpacklo_epi64(even, odd));
    let sbits = _mm256_add_epi64(_mm256_unpackhi_epi64(even, odd), top);
    let r2 = _mm256_mul_pd(r, r);
    let p23 = _mm256_fmadd_pd(r, _mm256_set1_pd(C3), _mm256_set1_pd(C2));
    let p45 = _mm256_fmadd_pd(r, _mm256_set1_pd(C5), _mm256_set1_pd(C4));
    let tmp = _mm256_fmadd_pd(p23, r2, _mm256_add_pd(r, tail));
    let tmp = _mm256_fmadd_pd(_mm256_mul_pd(r2, r2), p45, tmp);
    let scale = _mm256_castsi256_pd(sbits);
    // glibc's special cases, told apart by the top 12 bits of |x|: tiny
    // |x| (zero included, common: a clean wheel on a clean rail) is
    // `1 + x`, in the register; |x| >= 512, infinities and NaN go to
    // `f64::exp`, lane by lane (rare: the lanes are looked at only then).
    let abstop = _mm256_and_si256(
        _mm256_srli_epi64::<52>(_mm256_castpd_si256(xv)),
        _mm256_set1_epi64x(0x7ff),
    );
    let tiny = _mm256_cmpgt_epi64(_mm256_set1_epi64x(TOP_TINY as i64), abstop);
    let large = _mm256_cmpgt_epi64(abstop, _mm256_set1_epi64x((TOP_TINY + TOP_SPAN - 1) as i64));
    let result = _mm256_blendv_pd(
        _mm256_fmadd_pd(scale, tmp, scale),
        _mm256_add_pd(_mm256_set1_pd(1.0), xv),
        _mm256_castsi256_pd(tiny),
    );
    let large = _mm256_movemask_pd(_mm256_castsi256_pd(large));
    if large == 0 {
        return result;
    }
    let (mut out, mut x) = ([0.0; 4], [0.0; 4]);
    _mm256_storeu_pd(out.as_mut_ptr(), result);
    _mm256_storeu_pd(x.as_mut_ptr(), xv);
    for (j, (o, &xi)) in out.iter_mut().zip(&x).enumerate() {
        if large & (1 << j) != 0 {
            *o = xi.exp();
        }
    }
    _mm256_loadu_pd(out.as_ptr())
}

#[cfg(target_arch = "x86_64")]
/// The table's (tail, bits) pair of `k` mod 128 as one 16-byte load: how
/// [`exp4_register`] and [`exp8_register`] read it, a lane at a time.
///
/// # Safety
/// The CPU must have SSE2 (every x86-64 CPU).
#[inline(always)]
unsafe fn table_pair(k: u64) -> std::arch::x86_64::__m128i {
    // In bounds: 2 (k mod 128) + 1 < 256.
    std::arch::x86_64::_mm_loadu_si128(TABLE.as_ptr().add(2 * (k as usize & 127)).cast())
}

/// Whether [`exp8_register`] and the other eight-lane code can run here:
/// AVX-512F beside AVX2 and FMA.
#[inline]
pub fn exp8_is_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        exp4_is_vectorised() && std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(target_arch = "x86_64")]
/// [`exp4_register`] on eight lanes (an AVX-512 register): each lane's
/// operations those of a lane there, in the same order, so the same bits.
/// Each lane's (tail, bits) pair of the table is one 16-byte load, as
/// there, and unpacks sort the eight pairs. On an Intel Xeon of the
/// project's these loads made the 3-day replay 1.3 % slower than two
/// gathers (`vgatherqpd`, `vpgatherqq`; medians of 30 interleaved runs);
/// on the AMD EPYC (Zen 4) that runs CI the gathers made it 2-6 % slower
/// (pair ratios 0.939, 0.966, 0.983 in rounds of 30, 30 and 60): there
/// they are slow, and on the chain from one contact's masses to the next.
///
/// # Safety
/// The CPU must have AVX-512F, AVX2 and FMA.
#[inline(always)]
pub unsafe fn exp8_register(xv: std::arch::x86_64::__m512d) -> std::arch::x86_64::__m512d {
    use std::arch::x86_64::*;
    let kd = _mm512_fmadd_pd(xv, _mm512_set1_pd(INV_LN2_N), _mm512_set1_pd(SHIFT));
    let ki = _mm512_castpd_si512(kd);
    let kd = _mm512_sub_pd(kd, _mm512_set1_pd(SHIFT));
    let r = _mm512_fmadd_pd(kd, _mm512_set1_pd(NEG_LN2_HI_N), xv);
    let r = _mm512_fmadd_pd(kd, _mm512_set1_pd(NEG_LN2_LO_N), r);
    // The table pair of k mod 128 a lane, as in exp4_register; the
    // exponent k / 128 goes to the top.
    let mut k = [0u64; 8];
    _mm512_storeu_si512(k.as_mut_ptr().cast(), ki);
    let pair = |j: usize| table_pair(k[j]);
    let two =
        |a: usize, b: usize| _mm256_inserti128_si256::<1>(_mm256_castsi128_si256(pair(a)), pair(b));
    // [tail0, bits0 | tail2, bits2 | ... | tail6, bits6] and the odd lanes'.
    let even = _mm512_inserti64x4::<1>(_mm512_castsi256_si512(two(0, 2)), two(4, 6));
    let odd = _mm512_inserti64x4::<1>(_mm512_castsi256_si512(two(1, 3)), two(5, 7));
    let top = _mm512_slli_epi64::<45>(ki);
    let tail = _mm512_castsi512_pd(_mm512_unpacklo_epi64(even, odd));
    let sbits = _mm512_add_epi64(_mm512_unpackhi_epi64(even, odd), top);
    let r2 = _mm512_mul_pd(r, r);
    let p23 = _mm512_fmadd_pd(r, _mm512_set1_pd(C3), _mm512_set1_pd(C2));
    let p45 = _mm512_fmadd_pd(r, _mm512_set1_pd(C5), _mm512_set1_pd(C4));
    let tmp = _mm512_fmadd_pd(p23, r2, _mm512_add_pd(r, tail));
    let tmp = _mm512_fmadd_pd(_mm512_mul_pd(r2, r2), p45, tmp);
    let scale = _mm512_castsi512_pd(sbits);
    let abstop = _mm512_and_si512(
        _mm512_srli_epi64::<52>(_mm512_castpd_si512(xv)),
        _mm512_set1_epi64(0x7ff),
    );
    let tiny = _mm512_cmplt_epi64_mask(abstop, _mm512_set1_epi64(TOP_TINY as i64));
    let large =
        _mm512_cmpgt_epi64_mask(abstop, _mm512_set1_epi64((TOP_TINY + TOP_SPAN - 1) as i64));
    let result = _mm512_mask_blend_pd(
        tiny,
        _mm512_fmadd_pd(scale, tmp, scale),
        _mm512_add_pd(_mm512_set1_pd(1.0), xv),
    );
    if large == 0 {
        return result;
    }
    let (mut out, mut x) = ([0.0; 8], [0.0; 8]);
    _mm512_storeu_pd(out.as_mut_ptr(), result);
    _mm512_storeu_pd(x.as_mut_ptr(), xv);
    for (j, (o, &xi)) in out.iter_mut().zip(&x).enumerate() {
        if large & (1 << j) != 0 {
            *o = xi.exp();
        }
    }
    _mm512_loadu_pd(out.as_ptr())
}

/// `__exp_data.tab` of optimized-routines: for k = 0..127, the tail (the
/// relative error of the double nearest `2^(k/128)`) and that double's
/// bits minus `k << 45`.
static TABLE: [u64; 256] = [
    0x0000000000000000,
    0x3ff0000000000000,
    0x3c9b3b4f1a88bf6e,
    0x3feff63da9fb3335,
    0xbc7160139cd8dc5d,
    0x3fefec9a3e778061,
    0xbc905e7a108766d1,
    0x3fefe315e86e7f85,
    0x3c8cd2523567f613,
    0x3fefd9b0d3158574,
    0xbc8bce8023f98efa,
    0x3fefd06b29ddf6de,
    0x3c60f74e61e6c861,
    0x3fefc74518759bc8,
    0x3c90a3e45b33d399,
    0x3fefbe3ecac6f383,
    0x3c979aa65d837b6d,
    0x3fefb5586cf9890f,
    0x3c8eb51a92fdeffc,
    0x3fefac922b7247f7,
    0x3c3ebe3d702f9cd1,
    0x3fefa3ec32d3d1a2,
    0xbc6a033489906e0b,
    0x3fef9b66affed31b,
    0xbc9556522a2fbd0e,
    0x3fef9301d0125b51,
    0xbc5080ef8c4eea55,
    0x3fef8abdc06c31cc,
    0xbc91c923b9d5f416,
    0x3fef829aaea92de0,
    0x3c80d3e3e95c55af,
    0x3fef7a98c8a58e51,
    0xbc801b15eaa59348,
    0x3fef72b83c7d517b,
    0xbc8f1ff055de323d,
    0x3fef6af9388c8dea,
    0x3c8b898c3f1353bf,
    0x3fef635beb6fcb75,
    0xbc96d99c7611eb26,
    0x3fef5be084045cd4,
    0x3c9aecf73e3a2f60,
    0x3fef54873168b9aa,
    0xbc8fe782cb86389d,
    0x3fef4d5022fcd91d,
    0x3c8a6f4144a6c38d,
    0x3fef463b88628cd6,
    0x3c807a05b0e4047d,
    0x3fef3f49917ddc96,
    0x3c968efde3a8a894,
    0x3fef387a6e756238,
    0x3c875e18f274487d,
    0x3fef31ce4fb2a63f,
    0x3c80472b981fe7f2,
    0x3fef2b4565e27cdd,
    0xbc96b87b3f71085e,
    0x3fef24dfe1f56381,
    0x3c82f7e16d09ab31,
    0x3fef1e9df51fdee1,
    0xbc3d219b1a6fbffa,
    0x3fef187fd0dad990,
    0x3c8b3782720c0ab4,
    0x3fef1285a6e4030b,
    0x3c6e149289cecb8f,
    0x3fef0cafa93e2f56,
    0x3c834d754db0abb6,
    0x3fef06fe0a31b715,
    0x3c864201e2ac744c,
    0x3fef0170fc4cd831,
    0x3c8fdd395dd3f84a,
    0x3feefc08b26416ff,
    0xbc86a3803b8e5b04,
    0x3feef6c55f929ff1,
    0xbc924aedcc4b5068,
    0x3feef1a7373aa9cb,
    0xbc9907f81b512d8e,
    0x3feeecae6d05d866,
    0xbc71d1e83e9436d2,
    0x3feee7db34e59ff7,
    0xbc991919b3ce1b15,
    0x3feee32dc313a8e5,
    0x3c859f48a72a4c6d,
    0x3feedea64c123422,
    0xbc9312607a28698a,
    0x3feeda4504ac801c,
    0xbc58a78f4817895b,
    0x3feed60a21f72e2a,
    0xbc7c2c9b67499a1b,
    0x3feed1f5d950a897,
    0x3c4363ed60c2ac11,
    0x3feece086061892d,
    0x3c9666093b0664ef,
    0x3feeca41ed1d0057,
    0x3c6ecce1daa10379,
    0x3feec6a2b5c13cd0,
    0x3c93ff8e3f0f1230,
    0x3feec32af0d7d3de,
    0x3c7690cebb7aafb0,
    0x3feebfdad5362a27,
    0x3c931dbdeb54e077,
    0x3feebcb299fddd0d,
    0xbc8f94340071a38e,
    0x3feeb9b2769d2ca7,
    0xbc87deccdc93a349,
    0x3feeb6daa2cf6642,
    0xbc78dec6bd0f385f,
    0x3feeb42b569d4f82,
    0xbc861246ec7b5cf6,
    0x3feeb1a4ca5d920f,
    0x3c93350518fdd78e,
    0x3feeaf4736b527da,
    0x3c7b98b72f8a9b05,
    0x3feead12d497c7fd,
    0x3c9063e1e21c5409,
    0x3feeab07dd485429,
    0x3c34c7855019c6ea,
    0x3feea9268a5946b7,
    0x3c9432e62b64c035,
    0x3feea76f15ad2148,
    0xbc8ce44a6199769f,
    0x3feea5e1b976dc09,
    0xbc8c33c53bef4da8,
    0x3feea47eb03a5585,
    0xbc845378892be9ae,
    0x3feea34634ccc320,
    0xbc93cedd78565858,
    0x3feea23882552225,
    0x3c5710aa807e1964,
    0x3feea155d44ca973,
    0xbc93b3efbf5e2228,
    0x3feea09e667f3bcd,
    0xbc6a12ad8734b982,
    0x3feea012750bdabf,
    0xbc6367efb86da9ee,
    0x3fee9fb23c651a2f,
    0xbc80dc3d54e08851,
    0x3fee9f7df9519484,
    0xbc781f647e5a3ecf,
    0x3fee9f75e8ec5f74,
    0xbc86ee4ac08b7db0,
    0x3fee9f9a48a58174,
    0xbc8619321e55e68a,
    0x3fee9feb564267c9,
    0x3c909ccb5e09d4d3,
    0x3feea0694fde5d3f,
    0xbc7b32dcb94da51d,
    0x3feea11473eb0187,
    0x3c94ecfd5467c06b,
    0x3feea1ed0130c132,
    0x3c65ebe1abd66c55,
    0x3feea2f336cf4e62,
    0xbc88a1c52fb3cf42,
    0x3feea427543e1a12,
    0xbc9369b6f13b3734,
    0x3feea589994cce13,
    0xbc805e843a19ff1e,
    0x3feea71a4623c7ad,
    0xbc94d450d872576e,
    0x3feea8d99b4492ed,
    0x3c90ad675b0e8a00,
    0x3feeaac7d98a6699,
    0x3c8db72fc1f0eab4,
    0x3feeace5422aa0db,
    0xbc65b6609cc5e7ff,
    0x3feeaf3216b5448c,
    0x3c7bf68359f35f44,
    0x3feeb1ae99157736,
    0xbc93091fa71e3d83,
    0x3feeb45b0b91ffc6,
    0xbc5da9b88b6c1e29,
    0x3feeb737b0cdc5e5,
    0xbc6c23f97c90b959,
    0x3feeba44cbc8520f,
    0xbc92434322f4f9aa,
    0x3feebd829fde4e50,
    0xbc85ca6cd7668e4b,
    0x3feec0f170ca07ba,
    0x3c71affc2b91ce27,
    0x3feec49182a3f090,
    0x3c6dd235e10a73bb,
    0x3feec86319e32323,
    0xbc87c50422622263,
    0x3feecc667b5de565,
    0x3c8b1c86e3e231d5,
    0x3feed09bec4a2d33,
    0xbc91bbd1d3bcbb15,
    0x3feed503b23e255d,
    0x3c90cc319cee31d2,
    0x3feed99e1330b358,
    0x3c8469846e735ab3,
    0x3feede6b5579fdbf,
    0xbc82dfcd978e9db4,
    0x3feee36bbfd3f37a,
    0x3c8c1a7792cb3387,
    0x3feee89f995ad3ad,
    0xbc907b8f4ad1d9fa,
    0x3feeee07298db666,
    0xbc55c3d956dcaeba,
    0x3feef3a2b84f15fb,
    0xbc90a40e3da6f640,
    0x3feef9728de5593a,
    0xbc68d6f438ad9334,
    0x3feeff76f2fb5e47,
    0xbc91eee26b588a35,
    0x3fef05b030a1064a,
    0x3c74ffd70a5fddcd,
    0x3fef0c1e904bc1d2,
    0xbc91bdfbfa9298ac,
    0x3fef12c25bd71e09,
    0x3c736eae30af0cb3,
    0x3fef199bdd85529c,
    0x3c8ee3325c9ffd94,
    0x3fef20ab5fffd07a,
    0x3c84e08fd10959ac,
    0x3fef27f12e57d14b,
    0x3c63cdaf384e1a67,
    0x3fef2f6d9406e7b5,
    0x3c676b2c6c921968,
    0x3fef3720dcef9069,
    0xbc808a1883ccb5d2,
    0x3fef3f0b555dc3fa,
    0xbc8fad5d3ffffa6f,
    0x3fef472d4a07897c,
    0xbc900dae3875a949,
    0x3fef4f87080d89f2,
    0x3c74a385a63d07a7,
    0x3fef5818dcfba487,
    0xbc82919e2040220f,
    0x3fef60e316c98398,
    0x3c8e5a50d5c192ac,
    0x3fef69e603db3285,
    0x3c843a59ac016b4b,
    0x3fef7321f301b460,
    0xbc82d52107b43e1f,
    0x3fef7c97337b9b5f,
    0xbc892ab93b470dc9,
    0x3fef864614f5a129,
    0x3c74b604603a88d3,
    0x3fef902ee78b3ff6,
    0x3c83c5ec519d7271,
    0x3fef9a51fbc74c83,
    0xbc8ff7128fd391f0,
    0x3fefa4afa2a490da,
    0xbc8dae98e223747d,
    0x3fefaf482d8e67f1,
    0x3c8ec3bc41aa2008,
    0x3fefba1bee615a27,
    0x3c842b94c3a9eb32,
    0x3fefc52b376bba97,
    0x3c8a64a931d185ee,
    0x3fefd0765b6e4540,
    0xbc8e37bae43be3ed,
    0x3fefdbfdad9cbe14,
    0x3c77893b4d91cd9d,
    0x3fefe7c1819e90d8,
    0x3c5305c14160cc89,
    0x3feff3c22b8f71f1,
];

#[cfg(test)]
mod tests {
    use super::*;

    /// splitmix64: a reproducible stream of arguments without a crate.
    fn next(state: &mut u64) -> u64 {
        *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn uniform(state: &mut u64, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (next(state) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Ulps between two doubles of the same sign.
    fn ulps(a: f64, b: f64) -> u64 {
        a.to_bits().abs_diff(b.to_bits())
    }

    /// Every lane against `f64::exp`: the same bits with glibc (whose
    /// algorithm and FMA order this is), else within an ulp.
    fn check(x: [f64; 4]) {
        let got = exp4(x);
        for (g, xi) in got.iter().zip(x) {
            let want = xi.exp();
            if want.is_nan() {
                assert!(g.is_nan(), "exp({xi:e}) = {g:e}, not NaN");
            } else if cfg!(target_env = "gnu") {
                assert_eq!(
                    g.to_bits(),
                    want.to_bits(),
                    "exp({xi:e}): {g:e} != {want:e}"
                );
            } else {
                assert!(ulps(*g, want) <= 1, "exp({xi:e}): {g:e} vs {want:e}");
            }
        }
    }

    /// The eight-lane exp gives each lane the four-lane one's bits.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn eight_lanes_are_four_lanes_bit_for_bit() {
        if !exp8_is_available() {
            return;
        }
        #[target_feature(enable = "avx2,fma,avx512f")]
        fn eight(x: [f64; 8]) -> [f64; 8] {
            use std::arch::x86_64::*;
            let mut out = [0.0; 8];
            // SAFETY: compiled for these features, called where the CPU has them.
            unsafe {
                _mm512_storeu_pd(out.as_mut_ptr(), exp8_register(_mm512_loadu_pd(x.as_ptr())))
            };
            out
        }
        let mut state = 2027;
        let mut arguments = vec![
            [
                0.0,
                -0.0,
                f64::NAN,
                f64::INFINITY,
                f64::NEG_INFINITY,
                709.78,
                -708.4,
                -745.2,
            ],
            [
                511.999, 512.0, -511.999, -512.0, 5.55e-17, -5.55e-17, 1e-310, -1e-310,
            ],
        ];
        for _ in 0..200_000 {
            arguments.push(std::array::from_fn(|_| uniform(&mut state, -40.0, 0.0)));
            arguments.push(std::array::from_fn(|_| uniform(&mut state, -760.0, 720.0)));
        }
        for x in arguments {
            // SAFETY: the CPU has the features (checked above).
            let got = unsafe { eight(x) };
            let halves = [
                exp4([x[0], x[1], x[2], x[3]]),
                exp4([x[4], x[5], x[6], x[7]]),
            ];
            for (j, g) in got.iter().enumerate() {
                let want = halves[j / 4][j % 4];
                assert!(
                    g.to_bits() == want.to_bits() || (g.is_nan() && want.is_nan()),
                    "exp({:e}): {g:e} != {want:e}",
                    x[j]
                );
            }
        }
    }

    #[test]
    fn every_lane_is_f64_exp() {
        let mut state = 2026;
        for _ in 0..2_500_000 {
            // The kernel's arguments: -m / m_ref, -dt / tau, -k rain (<= 0,
            // mostly small), and the whole range to the over/underflows.
            check(std::array::from_fn(|_| uniform(&mut state, -40.0, 0.0)));
            check(std::array::from_fn(|_| uniform(&mut state, -1.0, 1.0)));
            check(std::array::from_fn(|_| uniform(&mut state, -760.0, 720.0)));
            check(std::array::from_fn(|_| {
                // Magnitudes from 1e-30 to 1e3 on a log scale, both signs.
                let m = 10f64.powf(uniform(&mut state, -30.0, 3.0));
                if next(&mut state) & 1 == 0 {
                    m
                } else {
                    -m
                }
            }));
        }
        check([0.0, -0.0, f64::NAN, f64::INFINITY]);
        check([f64::NEG_INFINITY, 709.78, -708.4, -745.2]);
        check([511.999, 512.0, -511.999, -512.0]);
        check([5.55e-17, -5.55e-17, 5.56e-17, -5.56e-17]);
        check([f64::MIN_POSITIVE, -f64::MIN_POSITIVE, 1e-310, -1e-310]);
    }
}
