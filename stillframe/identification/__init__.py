"""Identification algorithms of thesis ch. 3 on numpy arrays: FRF, OKID, ERA, ERA/DC, modal
parameters, proportional damping, MKR, the identified-model file, the structure identified from a
closed loop's own records and the detection of its change. No middleware."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["change_detection", "daisy", "damping", "data_checks", "era", "frf", "hammer",
                "loop_structure", "mkr", "modal", "model_file", "n4sid", "okid", "order_selection",
                "pem", "pipeline", "plots", "predictor", "quality", "report", "residual_tests",
                "ssi_cov", "stabilization", "structure_model", "sweep", "tracker", "validation"],
    submod_attrs={
        "pipeline": ["identify"],
        "okid": ["okid"],
        "modal": ["modal_parameters"],
        "ssi_cov": ["identify_output_only"],
        "n4sid": ["identify_n4sid"],
        "damping": ["fit_proportional_damping"],
        "change_detection": ["ChangeDetector"],
        "loop_structure": ["identify_loop_structure"],
    },
)
