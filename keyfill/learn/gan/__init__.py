"""Generative tweening (Zhou et al. 2020): long-term in-betweening with a convolutional GAN.

Two networks do the work at inference (section 3.2 of the paper):

1. the *local motion generator* turns the keys (in the dense input format of
   Fig. 4) into every frame's local pose: a 6D root rotation and range-bounded
   Euler angles per joint, mapped to joint positions by the RC-FK layer;
2. the *global path predictor* turns those local joint positions into root
   velocities, summed to the root path.

A discriminator over overlapping sub-sequences trains the generator (least-squares
GAN); the path predictor is trained first, then frozen. Two config options add
Motion DNA (representative poses encoded into a style vector, section 3.5.1)
and partial keys (root paths, half bodies, 2-D keys; section 5).

Modules (each small, named for what it does):

* :mod:`~keyfill.learn.gan.config`: :class:`GanConfig`, the named width presets.
* :mod:`~keyfill.learn.gan.ranges`: each joint's Euler order and feasible range from a corpus.
* :mod:`~keyfill.learn.gan.rcfk`: the range-constrained forward kinematics layer (section 3.3).
* :mod:`~keyfill.learn.gan.layers`: the modified residual convolution (Eq. 6) and batch regularisation (Eq. 9).
* :mod:`~keyfill.learn.gan.network`: generator, Motion DNA encoder, discriminator and path predictor (Table 5).
* :mod:`~keyfill.learn.gan.losses`: Eqs. 5, 7, 8, 10 and the DNA losses, Eqs. 11-12.
* :mod:`~keyfill.learn.gan.features`: the dense keyframe input format (Fig. 4) and the sparse one of partial keys.
* :mod:`~keyfill.learn.gan.dna`: Motion DNA data: the bank of representative poses, Appendix D's draws.
* :mod:`~keyfill.learn.gan.poses`: corpus clips as root paths and root-relative joint positions.
* :mod:`~keyfill.learn.gan.sampling`: training sequences and key sampling (section 3.7, Appendix C).
* :mod:`~keyfill.learn.gan.task`: the training task of both stages for keyfill's training loop.
* :mod:`~keyfill.learn.gan.model`: model folders (kind ``"gan"``) and ``complete``.
* :mod:`~keyfill.learn.gan.quality`: the Motion DNA and partial-key figures of a model.
"""

KIND = "gan"
