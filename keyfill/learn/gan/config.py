"""Settings of the generative tweening model and its training (:class:`GanConfig`).

Layer widths come from a named preset (:data:`PRESETS`):

* ``"paper"``: the channel widths of Table 5 of Zhou et al. 2020;
* ``"cpu"`` (the default): the same layers (kernels, strides, residual ratios,
  so the same receptive fields) at about an eighth of the widths, small enough
  to train on a 2-core CPU in a few hours.

Every setting is a plain JSON value, so a model folder's ``config.json`` holds
the whole configuration and a ``--resume`` can compare it.

Lengths are frames, speeds metres per second, positions inside the networks
metres (file units times the skeleton's ``meters_per_unit``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from keyfill.errors import UsageError
from keyfill.limits import check_number

#: channel widths per network: encoder (6 layers), decoder (13 hidden layers), discriminator (6), path predictor (8)
PRESETS: dict[str, dict[str, list[int]]] = {
    "paper": {
        "encoder": [384, 384, 512, 512, 768, 1024],
        "decoder": [1024, 1024, 1024, 768, 768, 768, 768, 512, 512, 512, 512, 512, 512],
        "discriminator": [512, 512, 512, 512, 1024, 1024],
        "path": [128, 128, 256, 256, 256, 256, 128, 128],
    },
    "cpu": {
        "encoder": [48, 48, 64, 64, 96, 128],
        "decoder": [128, 128, 128, 96, 96, 96, 96, 64, 64, 64, 64, 64, 64],
        "discriminator": [48, 48, 64, 64, 96, 128],
        "path": [32, 32, 64, 64, 64, 64, 32, 32],
    },
}
_LAYERS = {"encoder": 6, "decoder": 13, "discriminator": 6, "path": 8}
#: the longest gap a key layout may have: twice the 318-frame receptive field of a latent step, as the
#: dense input copies each key halfway towards its neighbours (section 3.5; tested against the layers)
EFFECTIVE_RECEPTIVE_FIELD = 636
#: the longest gap with the sparse input format of partial-key models: a key is seen only where it is,
#: so a frame must have both keys within the 318-frame receptive field of a latent step
SPARSE_RECEPTIVE_FIELD = 318
#: the highest order of the binomial low-pass on the generator's angles (``output_smoothing``): 64 already
#: spreads a frame over about 8 frames either side (its standard deviation is 4 frames)
MAX_SMOOTHING = 64
#: the most channels of noise, style or Motion DNA encoder width (the paper's largest is 1024)
MAX_CHANNELS = 65536
#: the other numbers of a :class:`GanConfig`: (lowest, highest, lowest allowed?); rates and weights may be 0
_RANGES = {
    "dna_weight": (0, 1e6, True), "dna_seconds": (0, 1e4, False), "partial_fraction": (0, 1, True),
    "mask_scale": (0, 1e6, False), "short_gap_seconds": (0, 1e4, True), "jump_speed": (0, 1e3, True),
    "max_frames": (1, 10_000_000, True), "batch_size": (1, 10_000, True), "real_frames": (64, 65_536, True),
    "sequence_frames": (64, 65_536, True), "crops_per_sequence": (1, 10_000, True), "path_batch": (1, 100_000, True),
    "steps_per_epoch": (1, 10_000_000, True), "lr_generator": (0, 10, True), "lr_discriminator": (0, 10, True),
    "lr_path": (0, 10, True), "adv_weight": (0, 1e6, True), "br_weight": (0, 1e6, True),
    "joint_weight": (0, 1e6, True), "root_weight_start": (0, 1e6, True), "root_weight_end": (0, 1e6, True),
    "root_weight_every": (1, 10_000_000, True), "grad_clip": (0, 1e6, True), "path_epochs": (1, 1_000_000, True),
    "generator_epochs": (1, 1_000_000, True), "val_fraction": (0, 0.9, True), "val_sequences": (0, 100_000, True),
    "in_clip_fraction": (0, 1, True), "window_frames": (64, 65_536, True), "min_key_every": (1, 10_000, True),
    "max_key_every": (1, 10_000, True), "warmup_fraction": (0, 1, True), "ema_decay": (0, 1, True),
    "recon_weight": (0, 1e6, True), "foot_weight": (0, 1e6, True), "sketch_stretch": (0, 1, True),
}
#: the choices of the recipe's named settings; the first of each is the first recipe's (and the default, so
#: that model folders written before the setting existed load and give their old bytes)
CHOICES = {
    "residual_form": ("printed", "variance"),
    "output_init": ("default", "small", "zero"),
    "upsampling": ("transposed", "linear"),
    "root_input": ("centred", "key-relative"),
    "optimizer": ("rmsprop", "adam"),
    "lr_schedule": ("constant", "cosine"),
    "root_weight_schedule": ("steps", "run"),
    "base": ("none", "spline", "linear", "match"),
    "dna_source": ("any", "own"),
    "loss_form": ("squared", "distance"),
}
#: settings added after models were shipped, with their defaults: :meth:`GanConfig.to_json` leaves them out at
#: the default, so the config.json of older folders and what ``--resume`` compares keep their bytes
LATER_DEFAULTS = {"dna_norm": False, "dna_source": "any", "sketch_stretch": 0.0, "library": "", "matched_set": "",
                  "loss_form": "squared", "base_input": False}
#: the JSON value types each annotated field type accepts (an int where a float is expected)
_JSON_TYPES = {"int": (int,), "float": (int, float), "bool": (bool,), "str": (str,), "dict": (dict,)}
#: hidden width of the Motion DNA encoder per preset (Table 5: 1024), used by ``keyfill train gan --dna``
DNA_WIDTHS = {"paper": 1024, "cpu": 128}


@dataclass(frozen=True)
class GanConfig:
    """Architecture, data and training settings (both stages).

    Attributes:
        preset: name of the width preset the widths came from (``"custom"`` when changed).
        widths: channel widths per network (see :data:`PRESETS`).
        noise_dim: channels of Gaussian noise joined to every latent step (the first recipe's
            source of variety, drawn by the seed of ``complete``; the second recipe has none, and
            the seed draws the Motion DNA from the model's bank instead).
        style_dim: channels of the per-sequence style vector joined to every latent
            step (the Motion DNA vector ``w``; 0: none, the decoder then takes no style).
        dna_width: hidden width of the Motion DNA encoder (section 3.5.1, Table 5), which
            makes the style vector from representative poses; 0: no encoder (models
            trained before Motion DNA). Needs ``style_dim`` > 0.
        dna_weight: weight of each of the two DNA losses (Eqs. 11-12; Appendix A: 50).
        dna_seconds: one representative frame per this many seconds of the gaps between
            keys (Appendix D), and the shortest gap Eq. 12 places a pose in (3 s).
        dna_norm: the DNA encoder's vector ``w`` is layer-normalised over its ``style_dim`` channels
            (zero mean, unit variance per sequence, no learned scale) before the decoder takes it; without
            it the third recipe's ``w`` came out at RMS 0.07 beside the encoder's features at 0.69.
        dna_source: where an in-clip window's Motion DNA comes from: ``"any"`` one random training clip
            (as the long sequences'), ``"own"`` the clip the window is cut from, so the DNA describes the
            motion the reconstruction term asks for and the generator has a reason to read it.
        partial_keys: train on partial keys too (section 5), with the sparse input format
            (keyed coordinates at key frames and a 0/1 mask, Fig. 4's top rows), so the
            model serves whole, root-only, half-body and 2-D keys; ``max_gap`` is then at
            most 318 frames (a key is seen only where it is).
        partial_fraction: the share of training sequences keyed partially (the rest get
            whole poses), split equally between root paths, half bodies and 2-D keys.
        sketch_stretch: ``s`` > 0: half the 2-D-keyed training sequences of a partial-key model take
            their keys from a stick figure whose every bone, at every key, is scaled by
            ``exp(U(-s, s))`` (section 5.3's casually drawn keys); the key losses keep the true poses,
            so the model learns to lift uneven sketches to feasible poses. 0: exact 2-D keys only.
        mask_scale: the dense mask (distance to the nearest key, frames) is divided by this.
        sequence_frames: frames ``N`` of a generator training sequence (a multiple of 64).
        min_gap, max_gap: key gaps drawn in training, frames (the paper: up to 600 of
            its 636-frame effective receptive field); ``max_gap`` is also the largest
            gap ``complete`` accepts.
        short_gap_seconds: gaps up to this long take both keys from one clip (Appendix C).
        jump_speed: for a gap that jumps to another clip, the root moves at most this
            fast (m/s) between the two keys; distance grows with the gap.
        max_frames: the longest window ``complete`` fills at once (a longer key range is filled by
            overlapping windows, :mod:`keyfill.learn.gan.long_takes`).
        output_smoothing: inference only: the order of the binomial low-pass applied to the
            generator's range-mapped joint angles and root 6D values along time before forward
            kinematics (:func:`keyfill.learn.gan.rcfk.binomial_lowpass`; 0: none). The
            transposed convolutions of an undertrained generator leave period-2 and period-4
            ripples (docs/gan.md, Quality); order 4 removes the first and damps the second,
            and the angles stay inside their ranges. Training never smooths.
        batch_size: generator sequences per step (the paper: 4).
        real_frames: frames of each sequence the discriminator judges (a multiple of 64);
            real ones are crops of corpus clips, fake ones crops of generated sequences.
        crops_per_sequence: fake crops taken from each generated sequence (and as many real ones).
        path_batch: clips per path-predictor step.
        steps_per_epoch: steps in an epoch of either stage.
        lr_generator, lr_discriminator, lr_path: RMSprop learning rates.
        adv_weight, br_weight, joint_weight: loss weights (Appendix A: 1, 5, 300).
        root_weight_start, root_weight_end, root_weight_every: the root path loss weight
            grows by 1 every ``root_weight_every`` generator steps from start to end
            (Appendix A: 10 to 80 every 1000).
        grad_clip: gradient norm clipping per optimiser (0: none, as in the paper).
        path_epochs, generator_epochs: default epochs of ``steps_per_epoch`` steps per stage
            (40 and 40: 8,000 steps each; with the ``"cpu"`` widths on this project's 2-core
            machine, about 8 minutes on two threads and 1-1.5 hours on one; see docs/gan.md).
        val_fraction: share of the clips held out for validation (by a seeded draw).
        val_sequences: held-out sequences scored after each generator epoch.
        residual_form: how a residual layer joins its skip path (Eq. 6; :mod:`keyfill.learn.gan.layers`):
            ``"printed"`` as the paper prints it, ``"variance"`` ``sqrt(s) h + sqrt(1 - s) skip``, whose skip
            gain is 1 at every ratio (the printed form's is above 1, so activations grow through a stack).
        output_init: the generator's output convolution: ``"default"`` PyTorch's initialisation,
            ``"small"`` a tenth of it and a zero bias, so a fresh generator's pre-``tanh`` angles sit
            near 0, the middle of every joint's range, instead of at its limits; ``"zero"`` zero weights
            and bias (with a ``base``: a fresh generator gives that interpolation).
        upsampling: the decoder's up-sampling layers: ``"transposed"`` convolutions (Table 5), or
            ``"linear"`` interpolation by 2 then a convolution of kernel 3 (no checkerboard ripple).
        root_input: the root channels of the dense input: ``"centred"`` the nearest key's root position
            (the keys' mean ground position at 0; spans metres over a long sequence), ``"key-relative"``
            its ground offset from the straight line between the frame's two keys (0 at keys; bounded by
            the gap), the height kept.
        in_clip_fraction: the share of generator steps whose batch is in-clip windows
            (:func:`keyfill.learn.gan.sampling.clip_window`: keys every ``min_key_every`` to
            ``max_key_every`` frames, the LaFAN1 context layout, whole short clips; the ground truth of
            every frame known) instead of the paper's long sequences (Appendix C). 0: the paper's only.
        window_frames: frames of an in-clip window (a multiple of 64); a batch of them holds
            ``batch_size * sequence_frames // window_frames`` windows (as many frames as a long batch).
        min_key_every, max_key_every: key spacing of in-clip windows, frames.
        optimizer: ``"rmsprop"`` (section 3.7, PyTorch's defaults) or ``"adam"`` (betas 0.5, 0.999).
        lr_schedule: ``"constant"`` or ``"cosine"``: linear warm-up over ``warmup_fraction`` of the
            run's generator steps, then a cosine decay to a tenth of the rate.
        warmup_fraction: see ``lr_schedule``.
        ema_decay: with a value above 0, the model keeps the exponential moving average of the
            generator's weights with this decay per step, and saves that average (0: the last weights).
        root_weight_schedule: ``"steps"``: the root weight grows by 1 every ``root_weight_every`` steps
            (Appendix A, absolute); ``"run"``: it grows linearly from start to end over the run's steps.
        recon_weight: weight of the supervised reconstruction term on in-clip windows (a deviation from
            the paper: the mean squared root-relative joint position error, m^2, on frames between keys).
        foot_weight: weight of the foot-sliding term on in-clip windows: the mean squared horizontal
            speed (m/s)^2 of the foot joints on frames the ground truth has them in contact
            (:func:`keyfill.characters.feet.label_contacts`).
        base: what the generator's output is added to: ``"none"`` (the paper: the output is the pose),
            ``"spline"`` (keyfill's cubic spline) or ``"linear"`` (slerp and lerp, the LaFAN1 protocol's
            interpolation): the RC-FK values of that interpolation of the keys' rotations, and the root's
            path is its interpolation of the key roots instead of the path predictor's
            (:mod:`keyfill.learn.gan.spline_base`, the third recipe). Needs whole keys (not
            ``partial_keys``): partial keys have no rotations to interpolate. ``"match"``: the in-between
            ``--method match`` gives through the keys, its rotations and its root path
            (:mod:`keyfill.learn.gan.matched_base`, issue 45).
        loss_form: the reconstruction and foot-sliding terms as ``"squared"`` (mean squared joint distance,
            m^2, and squared foot speed, (m/s)^2: the second recipe's) or ``"distance"`` (mean joint distance, m, and
            foot speed, m/s: the figures the benchmarks report; a squared error rewards pulling every frame towards
            the mean motion, which lowered the squared error of a matched base and raised its mean distance).
        base_input: with a ``base``, the generator's encoder also reads the base (its ``6 + 3 D`` values on every
            frame, beside the keys' dense input), so its residual can depend on what it corrects. Without it the
            network sees the keys alone: enough for a spline, which the keys decide, but a matched base is one
            library stretch among many, and a residual blind to it can only learn the average correction
            (issue 45: 40 epochs of it left a matched base's held-out error where it was).
        library: with base ``"match"``, the shipped motion library (a name of
            :func:`keyfill.learn.installed_models.shipped`) the base is matched from when ``complete`` is given
            no ``--library``.
        matched_set: with base ``"match"``, the matched set of the training clips (a ``.npz`` of
            :mod:`keyfill.learn.gan.matched_base`; training only, every in-clip window is one of its rows).
        seed: the seed of the clip split and of every batch (epoch ``e`` draws from
            ``numpy.random.default_rng([seed, stage, e])``).
    """

    preset: str = "cpu"
    widths: dict = field(default_factory=lambda: {k: list(v) for k, v in PRESETS["cpu"].items()})
    noise_dim: int = 32
    style_dim: int = 0
    dna_width: int = 0
    dna_weight: float = 50.0
    dna_seconds: float = 3.0
    dna_norm: bool = False
    dna_source: str = "any"
    partial_keys: bool = False
    partial_fraction: float = 0.6
    sketch_stretch: float = 0.0
    mask_scale: float = 64.0
    sequence_frames: int = 1024
    min_gap: int = 1
    max_gap: int = 600
    short_gap_seconds: float = 3.0
    jump_speed: float = 1.5
    max_frames: int = 8192
    output_smoothing: int = 4
    batch_size: int = 4
    real_frames: int = 128
    crops_per_sequence: int = 4
    path_batch: int = 16
    steps_per_epoch: int = 200
    lr_generator: float = 1e-4
    lr_discriminator: float = 1e-4
    lr_path: float = 1e-4
    adv_weight: float = 1.0
    br_weight: float = 5.0
    joint_weight: float = 300.0
    root_weight_start: float = 10.0
    root_weight_end: float = 80.0
    root_weight_every: int = 1000
    grad_clip: float = 0.0
    path_epochs: int = 40
    generator_epochs: int = 40
    val_fraction: float = 0.05
    val_sequences: int = 8
    residual_form: str = "printed"
    output_init: str = "default"
    upsampling: str = "transposed"
    root_input: str = "centred"
    in_clip_fraction: float = 0.0
    window_frames: int = 256
    min_key_every: int = 15
    max_key_every: int = 90
    optimizer: str = "rmsprop"
    lr_schedule: str = "constant"
    warmup_fraction: float = 0.05
    ema_decay: float = 0.0
    root_weight_schedule: str = "steps"
    recon_weight: float = 0.0
    foot_weight: float = 0.0
    base: str = "none"
    loss_form: str = "squared"
    base_input: bool = False
    library: str = ""
    matched_set: str = ""
    seed: int = 0

    def __post_init__(self):
        for name, (low, high, low_ok) in _RANGES.items():
            check_number(f"GAN setting {name!r}", getattr(self, name), low, high, low_ok=low_ok)
        for name, n in _LAYERS.items():
            w = self.widths.get(name)
            if not isinstance(w, (list, tuple)) or len(w) != n or not all(isinstance(c, int) and c > 0 for c in w):
                raise UsageError(f"GAN widths[{name!r}] must be {n} positive integers, got {w!r}")
        if set(self.widths) != set(_LAYERS):
            raise UsageError(f"GAN widths name {sorted(self.widths)}; expected {sorted(_LAYERS)}")
        if not 0 <= self.output_smoothing <= MAX_SMOOTHING or self.output_smoothing % 2:
            raise UsageError(f"output_smoothing must be an even order from 0 to {MAX_SMOOTHING}, "
                             f"got {self.output_smoothing}")
        if self.sequence_frames % 64 or self.real_frames % 64 or self.real_frames < 64:
            raise UsageError("sequence_frames and real_frames must be positive multiples of 64")
        if not 1 <= self.min_gap <= self.max_gap:
            raise UsageError(f"key gaps need 1 <= min_gap <= max_gap, got {self.min_gap}, {self.max_gap}")
        if self.max_gap > EFFECTIVE_RECEPTIVE_FIELD:
            raise UsageError(f"max_gap {self.max_gap} is longer than the generator's effective receptive field "
                             f"({EFFECTIVE_RECEPTIVE_FIELD} frames): frames in such a gap could not see both keys")
        if not all(0 <= n <= MAX_CHANNELS for n in (self.noise_dim, self.style_dim, self.dna_width)):
            raise UsageError(f"noise_dim, style_dim and dna_width must be from 0 to {MAX_CHANNELS}")
        if self.dna_width and not self.style_dim:
            raise UsageError("a Motion DNA encoder (dna_width > 0) needs style_dim > 0 channels for its vector")
        if self.partial_keys and self.max_gap > SPARSE_RECEPTIVE_FIELD:
            raise UsageError(f"partial-key models see each key only where it is (the sparse input format): "
                             f"max_gap {self.max_gap} must be at most {SPARSE_RECEPTIVE_FIELD} frames")
        if self.real_frames > self.sequence_frames:
            raise UsageError("real_frames cannot exceed sequence_frames")
        for name, choices in CHOICES.items():
            if getattr(self, name) not in choices:
                raise UsageError(f"GAN setting {name!r} must be one of {', '.join(choices)}; got {getattr(self, name)!r}")
        if self.window_frames % 64 or self.real_frames > self.window_frames and self.in_clip_fraction > 0:
            raise UsageError("window_frames must be a multiple of 64 and at least real_frames")
        if self.sketch_stretch and not self.partial_keys:
            raise UsageError("sketch_stretch stretches the 2-D keys of partial-key training; it needs partial_keys")
        if (self.dna_norm or self.dna_source != "any") and not self.dna:
            raise UsageError("dna_norm and dna_source need a Motion DNA encoder (dna_width > 0)")
        if self.base != "none" and self.partial_keys:
            raise UsageError(f"base {self.base!r} interpolates the keys' rotations, which partial keys do not give; "
                             "train a partial-key model with base \"none\"")
        if self.base_input and self.base == "none":
            raise UsageError("base_input reads the base into the generator; it needs a base (spline, linear or match)")
        if self.base == "match" and self.in_clip_fraction < 1:
            raise UsageError("base \"match\" trains on in-clip windows of its matched set only: set "
                             "in_clip_fraction to 1")
        if self.min_key_every > self.max_key_every or self.max_key_every > self.max_gap:
            raise UsageError(f"in-clip key spacing needs min_key_every <= max_key_every <= max_gap, got "
                             f"{self.min_key_every}, {self.max_key_every}, {self.max_gap}")

    @classmethod
    def from_preset(cls, name: str, **changes) -> GanConfig:
        """The config with the widths of preset ``name`` (and other fields changed)."""
        if name not in PRESETS:
            raise UsageError(f"unknown GAN preset {name!r}; presets are {', '.join(PRESETS)}")
        widths = {k: list(v) for k, v in PRESETS[name].items()}
        return cls(preset=name, widths=widths, **changes)

    @property
    def dna(self) -> bool:
        """Whether the model has a Motion DNA encoder."""
        return self.dna_width > 0

    def to_json(self) -> dict:
        """The fields as JSON values; those of :data:`LATER_DEFAULTS` only where they differ from the default."""
        return {k: v for k, v in dataclasses.asdict(self).items() if LATER_DEFAULTS.get(k, object()) != v}

    @classmethod
    def from_json(cls, data: dict) -> GanConfig:
        """The config from :meth:`to_json` output; unknown keys, and values of another type than the field's
        (or numbers over ``keyfill.limits.max_abs()`` in size), are a :class:`UsageError`."""
        from keyfill.limits import max_abs

        types = {f.name: f.type for f in dataclasses.fields(cls)}  # names of types: annotations are strings
        unknown = set(data) - set(types)  # fields added later (Motion DNA, partial keys) take their defaults
        if unknown:
            raise UsageError(f"unknown GAN setting {min(unknown)!r}")
        for name, value in data.items():
            if type(value) not in _JSON_TYPES[types[name]]:
                raise UsageError(f"GAN setting {name!r} must be of type {types[name]}, not {value!r:.40}")
            if type(value) in (int, float) and not abs(value) <= max_abs():
                raise UsageError(f"GAN setting {name!r} is {value:g}, more than {max_abs():g} in size")
        return cls(**data)

    def root_weight(self, step: int, steps: int) -> float:
        """The root path loss weight at generator step ``step`` of a run of ``steps`` (``root_weight_schedule``)."""
        if self.root_weight_schedule == "run":
            share = min(step / max(steps - 1, 1), 1.0)
            return float(self.root_weight_start + share * (self.root_weight_end - self.root_weight_start))
        grown = self.root_weight_start + step // max(self.root_weight_every, 1)
        return float(min(grown, self.root_weight_end))
