"""Pieces shared by the lab's samplers: the base class, the one key scheme,
hashing, Owen scrambling, the (0,2)-sequence and the wavefront index math.

How a Python sampler lives inside ``mi.render``
-----------------------------------------------
Mitsuba renders one wavefront of ``pixels x spp`` lanes; lane ``i`` traces
sample ``i mod spp`` of pixel ``i div spp`` (``wavefront_layout``). The C++
trampoline of ``mi.Sampler`` lets Dr.Jit traverse the Python attributes of a
sampler, so a symbolic loop (C++ ``path`` or a lab integrator) carries every
Dr.Jit array stored on ``self`` as loop state. Two rules follow:

* all state that changes per sample (the dimension counter ``self.dim``, a
  PCG32) is a Dr.Jit array, never a Python int: a Python int would be frozen
  into the traced loop body;
* everything that depends on the render seed is derived from an *opaque*
  array, so a new seed reuses the compiled kernel (no recompilation).

Python ints (``spp``, bit counts, the image width) are baked into the kernel:
changing them compiles a new kernel, as Mitsuba's own samplers do.

Keys
----
Every random choice of every lab sampler comes from one scheme, in two steps:

1. ``unit_key(seed, unit)``, once per render: the key of a *unit* (a pixel, a
   wavefront lane, or ``IMAGE`` for a sequence shared by the whole image) is
   TEA of (render seed, unit index), as Mitsuba seeds its own samplers;
2. ``sample_key(unit_key, dim, pass_index, purpose)``, per request: the key of
   one decision about that unit at one dimension of one pass, for one
   ``purpose`` (the index shuffle, the x or y scramble, a jitter, ...).

TEA is strong but costs about 80 integer operations; step 2 costs one or two
MurmurHash3 finalisers, and the unit keys are kept as sampler state.
"""
from __future__ import annotations

import math
import warnings

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.variant import plugin_settings

#: 2^-32: maps a uint32 to [0, 1).
INV_2_32 = 2.0 ** -32
#: Largest float32 below 1.
ONE_MINUS_EPS = float.fromhex("0x1.fffffep-1")


# ----------------------------------------------------------------------------
# Hashing and keys
# ----------------------------------------------------------------------------

def mix32(x):
    """MurmurHash3's 32-bit finaliser (Appleby 2008): a bijective avalanche mix."""
    x = mi.UInt32(x)
    x ^= x >> 16
    x *= 0x85EBCA6B
    x ^= x >> 13
    x *= 0xC2B2AE35
    x ^= x >> 16
    return x


#: The unit of keys shared by every pixel (a sequence that spans the image, as
#: lab_zsobol's): apart from every pixel and lane index of a 32-bit wavefront.
IMAGE = 0xFFFFFFFF

#: Purposes of ``sample_key``: which decision about a (unit, dimension, pass) a
#: key randomises. A sampler that keys pixels and lanes alike uses distinct
#: purposes on the two (a pixel's and a lane's keys share their TEA input).
PERMUTE = 0x9E3779B9      # the shuffle of the sample indices (padding)
SCRAMBLE_X = 0x85EBCA6B   # Owen scrambling of the first coordinate
SCRAMBLE_Y = 0xC2B2AE35   # ... and of the second
JITTER_X = 0x27D4EB2F     # a uniform offset in a stratum, first coordinate
JITTER_Y = 0x165667B1     # ... and second
BLOCKS = 0xD3A2646C       # lab_zsobol's order of the pixel blocks, shared by all dimensions


def unit_keys(seed_value, unit):
    """Both 32-bit words of TEA (4 rounds; Zafar et al. 2010) of (render seed, unit).

    Mitsuba's C++ samplers seed lane i's PCG32 with exactly these two words of
    (seed, i); ``lab_independent`` does the same and so renders identical images.
    (Feeding the lane index to PCG32 as its stream would be a mistake: streams
    with consecutive increments are correlated.)
    """
    return mi.sample_tea_32(mi.UInt32(seed_value), mi.UInt32(unit))


def unit_key(seed_value, unit):
    """The key of a unit (pixel, lane or ``IMAGE``) for one render: the first TEA word."""
    return unit_keys(seed_value, unit)[0]


def sample_key(key, dim, pass_index, purpose: int | None = None):
    """The key of one decision: unit (by its key, ``unit_key``), dimension, pass, purpose.

    ``w = dim | pass << 24`` is injective for dimensions < 2^24 and passes < 2^8,
    and ``unit_key + w * odd`` followed by the bijective ``mix32`` keeps distinct
    (dimension, pass) of one unit distinct; the unit key is already a hash, so one
    round suffices. A ``purpose`` (``PERMUTE``, ``SCRAMBLE_X``, ...) is mixed in by a
    second round, so the keys of one (unit, dimension, pass) for different purposes
    are unrelated. Dr.Jit merges repeated calls with equal arguments, so asking
    for several purposes hashes the (unit, dimension, pass) once.
    """
    word = mi.UInt32(dim) | (mi.UInt32(pass_index) << 24)
    key = mix32(mi.UInt32(key) + word * 0x9E3779B1)
    return key if purpose is None else mix32(key ^ purpose)


def to_unit_float(x):
    """uint32 -> float32 in [0, 1): the top 24 bits, so the result is never 1."""
    return to_float(mi.UInt32(x) >> 8) * (2.0 ** -24)


def to_float(x):
    """uint32 below 2^31 -> float32 through the *signed* conversion: AVX2 has a
    single instruction for int32 -> float32 and none for uint32 (LLVM emits a
    multi-instruction sequence), and the two agree below 2^31."""
    return mi.Float(mi.Int32(x))


# ----------------------------------------------------------------------------
# Base-2 points and Owen scrambling
# ----------------------------------------------------------------------------

def sobol_02(index, n_bits: int):
    """First two dimensions of the Sobol sequence as uint32 (the (0,2)-sequence).

    Dimension 0 is the van der Corput sequence (bit reversal of ``index``);
    dimension 1 multiplies the index bits by the upper-triangular Pascal matrix
    mod 2 (direction numbers v_0 = 2^31, v_k = v_{k-1} ^ (v_{k-1} >> 1)).
    By Lucas' theorem C(k, j) is odd iff the bits of j are a subset of those of
    k, so bit j of the product is the xor of the index bits k that are
    supersets of j: a subset-sum (zeta) transform over the bit positions, done
    in ceil(log2 n_bits) shift-mask-xor steps instead of one step per bit.
    Only the ``n_bits`` low bits of ``index`` are read (the caller guarantees
    ``index < 2^n_bits``).
    """
    index = mi.UInt32(index)
    x = dr.brev(index)
    if n_bits <= 0:
        return x, mi.UInt32(0)
    z = index
    for b, mask in enumerate(_ZETA_MASKS):
        if (1 << b) >= n_bits:
            break
        z ^= (z >> (1 << b)) & mask
    return x, dr.brev(z)


#: Bit positions j whose bit b is 0, for b = 0..4 (the zeta transform's steps).
_ZETA_MASKS = (0x55555555, 0x33333333, 0x0F0F0F0F, 0x00FF00FF, 0x0000FFFF)


def owen_scramble_2(v, seed):
    """Nested uniform (Owen) scrambling of a 32-bit base-2 fraction by hashing.

    Burley 2020, "Practical Hash-based Owen Scrambling", after Laine & Karras
    2011: on the bit-reversed value, adding the seed, multiplying by odd
    numbers and xoring with products by even numbers only carry changes from
    low to high bits, so after reversing back each output bit flips as a
    function of the seed and the *more significant* input bits only: a nested
    scramble. It keeps the (t,m,s)-net structure and makes each point uniform
    on [0, 1). The constants are Vegdahl's improved hash (also pbrt-v4's
    FastOwenScrambler), which scrambles the low bits better than Burley's
    original four xor-multiply steps.
    """
    return _owen_reversed(dr.brev(mi.UInt32(v)), seed)


def _owen_reversed(r, seed):
    """``owen_scramble_2`` of ``brev(r)``, given ``r`` itself (one bit reversal fewer)."""
    seed = mi.UInt32(seed)
    x = mi.UInt32(r)
    x ^= x * 0x3D20ADEA
    x += seed
    x *= (seed >> 16) | 1
    x ^= x * 0x05526C56
    x ^= x * 0x53A22864
    return dr.brev(x)


def sobol_02_owen(index, n_bits: int, seed_x, seed_y=None):
    """Owen-scrambled (0,2)-sequence point(s) at ``index``: equal to
    ``owen_scramble_2`` of each ``sobol_02`` coordinate, with two bit reversals
    instead of six (the x coordinate is brev(index), and both coordinates are
    reversed again inside the scramble). ``seed_y=None``: x only (a 1D request)."""
    index = mi.UInt32(index)
    x = _owen_reversed(index, seed_x)
    if seed_y is None:
        return x, None
    z = index
    for b, mask in enumerate(_ZETA_MASKS):
        if (1 << b) >= n_bits:
            break
        z ^= (z >> (1 << b)) & mask
    return x, _owen_reversed(z, seed_y)


def padded_index(sample_index, n_samples: int, seed):
    """Random permutation of the sample indices 0..n-1, one per ``seed``.

    Kensler 2013 ("Correlated Multi-Jittered Sampling"), the numbers of Mitsuba's
    ``mi.permute_kensler``: any n, and independent seeds give independent
    shuffles, which decorrelates dimension pairs of a padded sampler. For a power
    of two n the hash maps [0, n) into itself, so Mitsuba's cycle-walking loop
    always stops after one round; that round is inlined here (no loop in the
    kernel, same numbers). Other counts call Mitsuba's, loop included.
    """
    if n_samples == 1:
        return mi.UInt32(0) * mi.UInt32(sample_index)
    if not is_power_of_two(n_samples):
        return mi.permute_kensler(mi.UInt32(sample_index), n_samples, mi.UInt32(seed))
    w, seed = n_samples - 1, mi.UInt32(seed)
    i = mi.UInt32(sample_index) ^ seed
    i *= 0xE170893D
    i ^= seed >> 16
    i ^= (i & w) >> 4
    i ^= seed >> 8
    i *= 0x0929EB3F
    i ^= seed >> 23
    i ^= (i & w) >> 1
    i *= 1 | seed >> 27
    i *= 0x6935FA69
    i ^= (i & w) >> 11
    i *= 0x74DCB303
    i ^= (i & w) >> 2
    i *= 0x9E501CC3
    i ^= (i & w) >> 2
    i *= 0xC860A3DF
    i &= w
    i ^= i >> 5
    return (i + seed) & w


def morton_2d(x, y, n_bits: int):
    """Interleave the low ``n_bits`` bits of x (even bits) and y (odd bits)."""
    x, y = mi.UInt32(x), mi.UInt32(y)
    code = mi.UInt32(0)
    for k in range(n_bits):
        code |= ((x >> k) & 1) << (2 * k)
        code |= ((y >> k) & 1) << (2 * k + 1)
    return code


def log2_ceil(n: int) -> int:
    """Smallest k with 2^k >= n (n >= 1)."""
    return max(0, (int(n) - 1).bit_length())


def is_power_of_two(n: int) -> bool:
    return n > 0 and (n & (n - 1)) == 0


# ----------------------------------------------------------------------------
# Base class
# ----------------------------------------------------------------------------

class LabSampler(mi.Sampler):
    """Base of every lab sampler: parameters, seeding, wavefront layout, clone.

    Subclasses set ``plugin_name`` and implement ``_seed_state`` (per-render
    arrays, called with the opaque combined seed), ``_sample_1d(dim)`` and
    ``_sample_2d(dim)``; ``dim`` is the index of the first dimension the call
    consumes (a 1D request uses one, a 2D request two, as in pbrt), a Python
    int where it is known at trace time and a UInt32 array otherwise
    (``_current_dim``). The base keeps the dimension counter as an opaque
    Dr.Jit array so symbolic loops carry it.
    """

    plugin_name = "lab_sampler"
    #: Declared parameters (``plugins/params.py``): sample_count and seed here, each
    #: sampler's own added there (``params.LAB_STRATIFIED``, ...).
    PARAMETERS = params.SAMPLER
    #: Whether a power-of-two sample count matters (a warning otherwise).
    prefers_power_of_two = False
    #: Names of Python-level settings copied by ``clone``/``fork`` (besides props).
    _settings: tuple[str, ...] = ()

    def __init__(self, props: mi.Properties):
        cls = type(self)
        # Checked first: the C++ base reads sample_count and seed itself, and its own type
        # errors must not come first (nor refuse an integral float such as 8.0).
        values = plugin_settings(cls.plugin_name, props, cls.PARAMETERS, "sampler")
        # A copy with the normalised values: the Properties passed to the constructor die with
        # mi.load_dict, and clone() builds a twin from it later (a stored reference dangles).
        own = mi.Properties(props)
        own["sample_count"] = values["sample_count"]
        own["seed"] = values["seed"]
        super().__init__(own)
        self._props = own
        #: The declared parameters as read (``settings()``; subclasses take their own from it).
        self._values = values
        self.base_seed = values["seed"]
        self.spp = values["sample_count"]
        self._warned_spp = None
        self.dim = dr.opaque(mi.UInt32, 0)
        self.pass_index = dr.opaque(mi.UInt32, 0)
        self._static_dim = None

    # -- layout ----------------------------------------------------------------
    def wavefront_layout(self, wavefront_size: int, spp: int):
        """Lane i -> (pixel i div spp, sample i mod spp), as Mitsuba lays out a wavefront."""
        lane = dr.arange(mi.UInt32, wavefront_size)
        return lane // spp, lane % spp

    # -- mi.Sampler interface --------------------------------------------------
    def seed(self, seed, wavefront_size: int = 2 ** 32 - 1):
        super().seed(seed, wavefront_size)
        n = self.wavefront_size()
        spp = int(self.sample_count())
        self.spp = spp
        if self.prefers_power_of_two and not is_power_of_two(spp) and self._warned_spp != spp:
            warnings.warn(f"{self.plugin_name}: sample_count={spp} is not a power of two; "
                          f"{1 << log2_ceil(spp)} keeps the point set a full (0,m,2)-net", stacklevel=2)
            self._warned_spp = spp
        # Opaque: the seed value is a kernel input, not a constant of the kernel
        # (a literal seed would compile a new kernel for every seed).
        if isinstance(seed, int):
            seed_value = dr.opaque(mi.UInt32, (self.base_seed + seed) % 2 ** 32)
        else:
            seed_value = mi.UInt32(seed)
            dr.make_opaque(seed_value)
            seed_value = seed_value + dr.opaque(mi.UInt32, self.base_seed)
        self.pass_index = dr.opaque(mi.UInt32, 0)
        self._restart_dims()
        self._seed_state(seed_value, n, spp)

    def advance(self):
        """Next pass of a multi-pass render: fresh scrambles, dimension 0.

        Lab samplers do not know the pass layout (Mitsuba keeps
        ``samples_per_wavefront`` private), so a new pass is an independent
        randomisation of the same per-pixel point set: unbiased, but points
        of different passes are not jointly stratified.
        """
        super().advance()
        self.pass_index = self.pass_index + 1
        self._restart_dims()

    # -- dimension counter -----------------------------------------------------
    #: Hand subclasses the dimension as a Python int where it is known (see _current_dim).
    static_dims = True

    def _restart_dims(self):
        """Back to dimension 0 (a new render or pass); subclasses reset state that follows
        the dimension counter here."""
        self.dim = dr.opaque(mi.UInt32, 0)
        self._track_dim(0)

    def _track_dim(self, value: int | None):
        """Remember that ``self.dim`` (this very Dr.Jit variable) holds ``value``."""
        self._static_dim = None if value is None else (value, self.dim.index)

    def _current_dim(self):
        """The dimension counter as a Python int where its value is known, else the array.

        The requests an integrator makes before its path loop (the pixel
        position) happen in program order, so the counter is known at trace
        time; a subclass can then unroll work that depends on the dimension
        (lab_halton's digit count) instead of looping over it at run time.
        Inside a symbolic loop or call, or once anything else has replaced
        ``self.dim`` (a loop writing back its state, ``clone``), the value is
        only known to the kernel, and the array is returned. Both paths must
        give the same numbers (tested).
        """
        known = self._static_dim
        if (self.static_dims and known is not None and known[1] == self.dim.index
                and not dr.flag(dr.JitFlag.SymbolicScope)):
            return known[0]
        return self.dim

    def _next(self, sample, n_dims: int):
        dim = self._current_dim()
        value = sample(dim)
        self.dim = self.dim + n_dims
        self._track_dim(dim + n_dims if isinstance(dim, int) else None)
        return value

    def next_1d(self, active=True):
        return self._next(self._sample_1d, 1)

    def next_2d(self, active=True):
        return self._next(self._sample_2d, 2)

    def _state_names(self) -> list[str]:
        return [k for k, v in self.__dict__.items() if dr.is_array_v(v) or isinstance(v, mi.PCG32)]

    def schedule_state(self):
        dr.schedule(*[getattr(self, k) for k in self._state_names()])

    def _copy_settings(self, other: "LabSampler", with_state: bool) -> "LabSampler":
        other.set_sample_count(self.sample_count())
        other.spp = self.spp
        other._warned_spp = self._warned_spp
        for k in self._settings:
            setattr(other, k, getattr(self, k))
        if with_state and self.wavefront_size() > 0:
            # Re-seeding the C++ base records the wavefront size; the arrays are
            # then copied (Dr.Jit's in-place operators must not touch the original).
            mi.Sampler.seed(other, mi.UInt32(0), self.wavefront_size())
            for k in self._state_names():
                v = getattr(self, k)
                setattr(other, k, mi.PCG32(v) if isinstance(v, mi.PCG32) else type(v)(v))
        return other

    def clone(self):
        return self._copy_settings(type(self)(self._props), with_state=True)

    def fork(self):
        return self._copy_settings(type(self)(self._props), with_state=False)

    def settings(self) -> dict:
        """The parameters in force, every declared one in declaration order (equal to
        ``params.resolve(plugin_name, given)`` until a render sets another sample count)."""
        values = {p.name: getattr(self, p.name, self._values[p.name]) for p in self.PARAMETERS}
        values["sample_count"] = int(self.sample_count())
        values["seed"] = self.base_seed
        return values

    def to_string(self):
        extra = "".join(f", {k}={getattr(self, k)!r}" for k in self._settings)
        return f"{type(self).__name__}[sample_count={self.sample_count()}, seed={self.base_seed}{extra}]"

    # -- subclass hooks --------------------------------------------------------
    def _seed_state(self, seed_value, wavefront_size: int, spp: int):
        raise NotImplementedError

    def _sample_1d(self, dim):
        raise NotImplementedError

    def _sample_2d(self, dim):
        raise NotImplementedError


class Base2PairSampler(LabSampler):
    """A lab sampler whose requests come from ``_scrambled(dim, two_d)``: a pair of
    scrambled base-2 uint32 coordinates (the second None for a 1D request)."""

    def _scrambled(self, dim, two_d: bool):
        raise NotImplementedError

    def _sample_1d(self, dim):
        return to_unit_float(self._scrambled(dim, False)[0])

    def _sample_2d(self, dim):
        x, y = self._scrambled(dim, True)
        return mi.Point2f(to_unit_float(x), to_unit_float(y))


def isqrt_exact(n: int) -> int | None:
    r = math.isqrt(n)
    return r if r * r == n else None
