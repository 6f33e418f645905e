"""The lamp ARNN (Zhang & van de Panne 2018): ``network`` (torch), ``features``, ``model`` (load, complete), ``task``
(training), ``onnx`` (export and the torch-free runtime). See docs/arnn.md."""
