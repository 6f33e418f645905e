"""The motion-completion transformer (Duan et al. 2021): ``config``, ``network`` (torch), ``features``, ``model``
(load, complete), ``task`` (training), ``onnx`` (export and the torch-free runtime). See docs/transformer.md."""
