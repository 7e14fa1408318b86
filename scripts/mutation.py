"""Mutation testing of the numerical core (issue 21), run outside the default CI: it is slow.

For each target module, mutmut (docs/dependencies.md) makes every single-token change it knows (an
operator, a constant, an argument dropped, a comparison flipped, ...) and runs, for each mutant, the
unit tests of that module that call the mutated function. A mutant is *killed* when a test fails (or
times out), *survives* when all of them pass, *no tests* when none of the selected tests reaches its
function. The score is killed / (killed + survived + no tests); only the module's fast unit test files
are selected (listed below), so the score is a lower bound on what the whole default suite catches.

Each target is mutated in its own copy of the tracked files under ``--work`` (mutmut keeps its
results in ``mutants/`` there, so an interrupted run resumes where it stopped). The results go to
``--out`` (JSON: per target, the counts and every surviving mutant's diff) and a table is printed.
docs/validation.md ("Mutation testing") holds the latest numbers and, for every survivor, the test
that now kills it or the reason it cannot change a number a user reads.

Usage::

    pip install mutmut==3.8.1
    python scripts/mutation.py                         # every target (about 15 min on 2 cores)
    python scripts/mutation.py --only lumped summary   # some targets
    python scripts/mutation.py --only likelihood --sample 400 --seed 38   # a random 400 of a long target's mutants
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from fnmatch import fnmatch
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: target -> (the file mutated, the unit test files that may kill its mutants, the functions mutated:
#: mutmut's mutant-name patterns, None for every function of the file)
TARGETS: dict[str, tuple[str, list[str], list[str] | None]] = {
    "lumped": ("bayesrod/physics/lumped.py", ["tests/test_lumped.py"], None),
    "effects": ("bayesrod/physics/effects.py", ["tests/test_effects.py"], None),
    "summary": ("bayesrod/inference/summary.py", ["tests/test_summary.py"], None),
    "noise": (
        "bayesrod/inference/likelihood.py",
        [  # the exact-density tests (the fits in these files would make each mutant take minutes)
            "tests/test_noise.py::test_ar1_loglik_is_the_exact_gaussian_density",
            "tests/test_noise.py::test_ar1_and_shared_error_densities_batch_over_leading_axes",
            "tests/test_width.py::test_width_term_matches_a_dense_gaussian_reference",
        ],
        ["*.x_ar1_innovations__mutmut_*", "*.x_ar1_loglik__mutmut_*", "*.x_shared_error_loglik__mutmut_*"],
    ),
    "curvature": ("bayesrod/vision/curvature.py", ["tests/test_curvature.py"], None),
    "priors": (
        "bayesrod/inference/priors.py",
        [
            "tests/test_priors.py",
            "tests/test_inference.py::test_prior_files_normalised_and_justified",
            "tests/test_inference.py::test_prior_errors",
        ],
        None,
    ),
    "compare": (
        "bayesrod/inference/hierarchical.py",
        [  # the species model's pieces by hand (test_compare.py's end-to-end runs take 10 s to 2 min each)
            "tests/test_hierarchical_units.py",
            "tests/test_compare.py::test_modulus_model_finds_a_thickness_difference",
        ],
        None,
    ),
    "design": ("bayesrod/inference/design.py", ["tests/test_design.py"], None),
    "elastica": (
        "bayesrod/physics/elastica.py",
        [  # the forward solver against Bisshopp-Drucker, small deflection and the reference solver, without
            # the two 20 s sweeps (test_forces_agree_with_reference_up_to_slip): a lower bound
            *(
                f"tests/test_elastica.py::{t}"
                for t in (
                    "test_bisshopp_drucker",
                    "test_bisshopp_drucker_force_to_shape",
                    "test_small_deflection_uniform",
                    "test_small_deflection_taper",
                    "test_force_to_contact_agrees_with_reference",
                    "test_slip_reported_not_invented",
                    "test_force_increases_monotonically_along_branch",
                    "test_EI0_is_a_pure_scale_and_length_scales",
                    "test_batching_matches_single_solves",
                    "test_shape_grid_matches_reference",
                    "test_impossible_inputs_raise_value_error",
                    "test_root_search_finds_roots_next_to_the_branch_end",
                    "test_plain_fast_step_matches_the_general_step",
                    "test_plain_step_per_element_matches_the_general_step",
                    "test_centerline_at_heights_matches_a_fine_resampling",
                    "test_plastic_branch_is_the_elastic_rod_on_a_base_turned_by_the_plastic_rotation",
                    "test_dimensional_solutions_report_every_field_in_si_units_and_round_trip",
                    "test_march_finds_a_contact_height_the_rod_only_reaches_inside_one_step",
                    "test_without_effects_the_measured_force_is_the_true_force",
                    "test_secant_k_theta_is_F_h_over_the_contact_rotation_from_rest_with_its_effects_and_steps",
                )
            ),
            "tests/test_root_search.py",  # the root search alone, on functions with known roots
            "tests/test_elastica_units.py",  # input checks and defaults (session 40)
            "tests/test_effects.py",
            "tests/test_lumped.py",  # secant_k_theta's tests
        ],
        None,
    ),
    "direct": (
        "bayesrod/inference/direct.py",
        [  # the estimator's pieces against hand computations (test_direct.py's fits take 20-60 s each)
            "tests/test_direct_units.py",
            "tests/test_direct.py::test_fit_p_recovers_slope_with_noisy_base_bins_and_needs_three_bins",
        ],
        None,
    ),
    "diagnose": (
        "bayesrod/inference/diagnose.py",
        ["tests/test_diagnose_refits.py", "tests/test_diagnose_starts.py"],
        [  # the statistics of the verdict (the fits themselves are checked by the slow tests)
            f"*.x_{f}__mutmut_*"
            for f in (
                "lag1",
                "heldout_comparison",
                "_ar1_noise",
                "null_heldout_gain",
                "_whiten_rows",
                "_legendre",
                "_first_passing",
                "_candidate_lr",
                "_scale_fit",
                "_hold",
            )
        ]
        + ["*.xǁDiagnoserǁstructure__mutmut_*"],
    ),
    "centerline": (  # added in session 31: the centerline term's normal offsets (session 30)
        "bayesrod/physics/elastica.py",
        [
            "tests/test_elastica.py::test_normal_offsets_match_the_nearest_point_of_a_fine_resampling",
            "tests/test_elastica.py::test_normal_offsets_of_many_centerlines_at_once_are_those_of_each_alone",
            "tests/test_inference.py::test_shape_tables_hold_a_noise_free_centerline_where_the_stem_lies_flat_between_nodes",
            "tests/test_diagnose.py::test_forward_model_reads_centerlines_as_the_fit_does",
            "tests/test_preload_shapes.py",
            "tests/test_shape_weight.py",
        ],
        ["*.x_centerline_normal_offsets__mutmut_*"],
    ),
    "shape_tables": (  # added in session 31: the likelihood's centerline tables and the compliance axis's range
        "bayesrod/inference/likelihood.py",
        [
            "tests/test_inference.py::test_shape_tables_hold_a_noise_free_centerline_where_the_stem_lies_flat_between_nodes",
            "tests/test_inference.py::test_the_compliance_axis_covers_a_stem_whose_base_spring_dominates",
            "tests/test_inference.py::test_the_ei0_range_of_an_effect_axis_is_the_estimate_within_a_factor_2_or_the_prior_without_forces",
            "tests/test_inference.py::test_shape_offsets_past_a_nodes_slip_go_on_along_the_secant_of_its_last_step",
            "tests/test_inference.py::test_likelihood_peaks_near_truth",
            "tests/test_inference.py::test_forces_only_and_shapes_only",
            "tests/test_preload_shapes.py",
            "tests/test_shape_weight.py",
        ],
        [
            "*.x_effect_axis_ei0_range__mutmut_*",
            "*.xǁRodLikelihoodǁ_shape_table__mutmut_*",
            "*.xǁRodLikelihoodǁshape_offsets__mutmut_*",
            "*.xǁRodLikelihoodǁshape_offsets_preloaded__mutmut_*",
        ],
    ),
    "table_zoom": (  # added in session 65: the fit's narrowing of a coarse effect axis (zoom_window)
        "bayesrod/inference/likelihood.py",
        ["tests/test_inference.py::test_zoom_window_narrows_only_a_coarse_axis_and_stays_inside_it"],
        ["*.x_zoom_window__mutmut_*", "*.x_effect_axis_label__mutmut_*"],
    ),
    "effect_axis_inverse": (  # added in session 67: an effect's value at a table coordinate, a node interval's middle
        "bayesrod/inference/likelihood.py",
        [
            "tests/test_inference.py::test_an_effect_axis_maps_its_coordinate_back_to_the_effect",
            "tests/test_inference.py::test_a_start_at_a_node_of_a_coarse_effect_axis_is_checked_between_nodes_too",
        ],
        ["*.xǁEffectAxisǁvalue__mutmut_*", "*.xǁEffectAxisǁbetween_nodes__mutmut_*"],
    ),
    "between_nodes": (  # added in session 67: the start's check also between nodes, the worse deciding
        "bayesrod/api/fitting.py",
        [
            "tests/test_inference.py::test_a_start_at_a_node_of_a_coarse_effect_axis_is_checked_between_nodes_too",
            "tests/test_inference.py::test_the_between_nodes_check_moves_only_the_effect_to_the_middle_of_its_node_interval",
        ],
        ["*.x__worse__mutmut_*", "*.x__check_between_nodes__mutmut_*"],
    ),
    "step_back": (  # added in session 31: the simulator's step back from a failed solve (session 30)
        "bayesrod/dataset/simulate.py",
        ["tests/test_simulate.py"],
        ["*.x__step_back__mutmut_*"],
    ),
    "sampler": (  # added in session 25 with the restart of stuck walkers; run in session 26 (docs/validation.md)
        "bayesrod/inference/sampler.py",
        ["tests/test_sampler.py", "tests/test_inference.py::test_sampler_resumes_from_checkpoint"],
        ["*.x_replace_stuck_walkers__mutmut_*", "*.x_run_ensembles__mutmut_*", "*.x__collect__mutmut_*"],
    ),
}

# added in session 34: the functions of the elastica target that no run reached (sessions 24-25 stopped
# before them), with the elastica target's tests
TARGETS["elastica_solver"] = (
    "bayesrod/physics/elastica.py",
    TARGETS["elastica"][1],
    [
        f"*.x_{f}__mutmut_*"
        for f in (
            "_problem",
            "_subset",
            "_prepare",
            "_rhs",
            "_step",
            "_march",
            "_at",
            "_locate",
            "_illinois",
            "_bracket_and_solve",
            "_equilibrium",
        )
    ],
)

# added in session 43: the solver's core against exact solutions (tests/test_elastica_core.py, about 3 s): the
# elastica target's tests take 60-80 s per surviving core mutant, too slow for its 1500 core mutants
TARGETS["elastica_core"] = (
    "bayesrod/physics/elastica.py",
    ["tests/test_elastica_core.py", "tests/test_root_search.py"],
    [
        f"*.x_{f}__mutmut_*"
        for f in (
            "_problem",
            "_subset",
            "_weighted",
            "_prepare",
            "_rhs",
            "_inverse_taper",
            "_plain_slopes",
            "_step_plain",
            "_step_plain_each",
            "_step",
            "_step_general",
            "_march",
            "_at",
            "_locate",
            "_too_far",
            "_illinois",
            "_bracket_and_solve",
            "_equilibrium",
            "_balance_base_moment",
        )
    ],
)

# added in session 49: the two functions session 46 rewrote (a march that bends back below the sensor has no contact;
# the base-moment search moves its bracket by the stem's class), run alone on the core's tests
TARGETS["moment_search"] = (
    "bayesrod/physics/elastica.py",
    TARGETS["elastica_core"][1],
    [f"*.x_{f}__mutmut_*" for f in ("_march", "_balance_base_moment")],
)

# added in session 68: the rest of the sampler (the convergence criteria of session 57: R-hat with the ensembles as
# chains, the walkers' R-hat, the targets missed and the message; the start; stuck walkers; the checkpoint)
TARGETS["sampler_rest"] = (
    "bayesrod/inference/sampler.py",
    ["tests/test_sampler.py", "tests/test_inference.py::test_sampler_resumes_from_checkpoint"],
    [
        f"*.x_{f}__mutmut_*"
        for f in (
            "diagnostics",
            "missed_targets",
            "convergence_message",
            "steps_needed",
            "stuck_walkers",
            "rhat_walkers_max",
            "count_stuck",
            "ensemble_seeds",
            "_ball",
            "find_start",
            "_profile_preloads",
        )
    ]
    + ["*.xǁCheckpointBackendǁ*"],
)

# added in session 35: the joint posterior of one stem under several conditions (issue 23) and its summary
TARGETS["group"] = ("bayesrod/inference/group.py", ["tests/test_group.py"], None)
TARGETS["group_summary"] = (
    "bayesrod/api/group.py",
    ["tests/test_group.py", "tests/test_compare_groups.py"],
    # session 52: the correlations' prior sensitivity and its warning
    [
        "*.x__summary__mutmut_*",
        "*.x_fit_group__mutmut_*",
        "*.x__evenly__mutmut_*",
        "*.x_sensitivity_draws__mutmut_*",
        "*.x_correlation_sensitivity__mutmut_*",
        "*.x__correlation_sensitivity__mutmut_*",
    ],
)
# session 54: the correlations' prior sensitivity (session 52) against the tests that call it on draws set by the
# test, without fit_group (whose MAP and sharing refits make group_summary's run take hours); the warning it
# composes (_correlation_sensitivity) is read only through fit_group: group_summary's
TARGETS["group_sensitivity"] = (
    "bayesrod/api/group.py",
    [
        "tests/test_group.py::test_correlation_sensitivity_thins_drops_non_finite_draws_and_reads_each_quantity",
        "tests/test_group.py::test_summaries_read_evenly_spaced_draws_up_to_their_count",
    ],
    ["*.x__evenly__mutmut_*", "*.x_sensitivity_draws__mutmut_*", "*.x_correlation_sensitivity__mutmut_*"],
)

# added in session 38: the force likelihood itself (the tables' interpolation, the residuals, the Gaussian and
# AR(1) sums, the offsets, the slip term, the posterior's log_prob), which no target held: only its noise
# densities and shape tables had been mutated. The tests: the likelihood's fast unit tests (no sampling)
TARGETS["likelihood"] = (
    "bayesrod/inference/likelihood.py",
    [  # without the table-accuracy and fit tests (5-25 s each): every table is rebuilt in each mutant's run
        *(
            f"tests/test_inference.py::{t}"
            for t in (
                "test_force_table_matches_direct_solves",
                "test_table_interpolation_weights_are_the_lagrange_cardinals",
                "test_likelihood_peaks_near_truth",
                "test_forces_only_and_shapes_only",
            )
        ),
        *(
            f"tests/test_noise.py::{t}"
            for t in (
                "test_table_log_likelihood_is_the_explicit_gaussian_density_of_its_residuals",
                "test_ar1_noise_is_sampled_by_its_innovation_sd_with_the_prior_kept_on_the_marginal_sd",
                "test_predictive_forces_of_a_preloaded_push_are_shifted_by_each_draws_preload",
            )
        ),
        *(
            f"tests/test_nuisances.py::{t}"
            for t in (
                "test_force_offsets_per_push_enter_the_residuals_of_their_own_push",
                "test_force_curve_cache_survives_eviction_within_one_batch",
                "test_geometry_tables_match_tables_built_at_that_geometry",  # 5 s: the residuals' geometry branch
            )
        ),
        *(
            f"tests/test_slip.py::{t}"
            for t in (
                "test_the_slip_window_brackets_the_simulated_slip_within_one_robot_step",
                "test_a_push_stopped_short_says_only_how_far_the_stem_held",
                "test_slip_term_is_the_probability_that_the_window_meets_the_model_slip_range",
                "test_the_model_slip_range_holds_the_simulators_slip_and_starts_where_the_force_is_within_its_tolerance",
                "test_the_slip_term_adds_to_the_likelihood_and_stays_out_of_held_out_refits",
                "test_the_slip_term_reads_the_tabled_effect_and_moves_its_window_with_the_preload",
            )
        ),
        "tests/test_likelihood_core.py",
    ],
    [
        *(f"*.x_{f}__mutmut_*" for f in ("_lagrange4", "_chain_starts", "scale_fit_rows", "force_scale_fit")),
        *(
            f"*.xǁ{c}ǁ{m}__mutmut_*"
            for c, ms in (
                ("ForceCurves", ("force", "_solve", "batch")),
                (
                    "RodLikelihood",
                    (
                        "_weights",
                        "_interp",
                        "_gather_weights",
                        "effect_coordinate",
                        "in_table",
                        "predict_nd_force_preloaded",
                        "predict_nd_force",
                        "residuals",
                        "_per_push",
                        "restricted",
                        "without_effect_axis",
                        "log_likelihood",
                        "_rho",
                        "_offset_column",
                        "offset_posterior",
                        "fit_error",
                        "slip_loglik",
                        "_slip_m",
                    ),
                ),
                ("PosteriorBase", ("log_prior", "_in_support", "log_prob")),
                ("LogPosterior", ("__init__", "_in_support")),
            )
            for m in ms
        ),
    ],
)

# added in session 39: the bands and predictions a user reads (issue 21, deliverable 4: the stated level is the
# level used), tested on posteriors made by hand (tests/test_bands_units.py: no fit, 15 s)
TARGETS["bands"] = (
    "bayesrod/api/fitting.py",
    ["tests/test_bands_units.py"],
    [
        *(f"*.x_{f}__mutmut_*" for f in ("_check_level", "_q_names", "_grid", "unseen_height")),
        *(
            f"*.xǁPosteriorǁ{m}__mutmut_*"
            for m in (
                "summary",
                "thinned",
                "_base_stiffness",
                "ei_band",
                "youngs_modulus",
                "modulus_band",
                "diameter_band",
                "k_theta_band",
                "_stiffness_band",
                "k_x_band",
                "predict_force",
            )
        ),
    ],
)
TARGETS["predict"] = ("bayesrod/api/predict.py", ["tests/test_bands_units.py", "tests/test_cli_predict.py"], None)
TARGETS["checks"] = ("bayesrod/inference/checks.py", ["tests/test_model_check_units.py"], None)
TARGETS["interval"] = ("bayesrod/api/_common.py", ["tests/test_bands_units.py"], ["*.x_interval__mutmut_*"])
# added in session 66: compare's and design's API layers (the species summaries, the anchorage, the default plan
# and heights, a condition's draws), where 19 of 22 hand mutants survived before (docs/validation.md, "Session 66")
TARGETS["compare_api"] = ("bayesrod/api/compare.py", ["tests/test_compare.py", "tests/test_compare_groups.py"], None)
TARGETS["design_api"] = ("bayesrod/api/design.py", ["tests/test_design.py", "tests/test_design_group.py"], None)

# added in session 40: the slip as a range (the term, its tables' lookup, the summary's report) and the
# engagement's change point (docs/validation.md, "The slip as a range; the engagement's change point")
TARGETS["slip"] = (
    "bayesrod/inference/likelihood.py",
    [
        *(
            f"tests/test_slip.py::{t}"
            for t in (
                "test_slip_term_is_the_probability_that_the_window_meets_the_model_slip_range",
                "test_the_model_slip_range_holds_the_simulators_slip_and_starts_where_the_force_is_within_its_tolerance",
                "test_the_slip_term_adds_to_the_likelihood_and_stays_out_of_held_out_refits",
                "test_the_slip_term_reads_the_tabled_effect_and_moves_its_window_with_the_preload",
                "test_the_summary_reports_the_data_slip_window_beside_the_model_slip",
                "test_a_push_stopped_short_says_only_how_far_the_stem_held",
                "test_the_slip_window_by_hand_with_a_stalled_robot_and_a_two_sample_push",
                "test_without_a_robot_step_the_slip_softening_is_half_a_percent_of_the_displacement",
            )
        ),
    ],
    [
        *(f"*.xǁRodLikelihoodǁ{m}__mutmut_*" for m in ("_init_slip", "_slip_m", "slip_displacement_m", "slip_loglik")),
        "*.x__slip_window__mutmut_*",
    ],
)
TARGETS["engagement"] = (
    "bayesrod/dataset/engagement.py",
    [
        "tests/test_engagement_units.py",
        "tests/test_slip.py::test_the_slip_window_brackets_the_simulated_slip_within_one_robot_step",
        "tests/test_importer.py",
    ],
    None,
)

# added in session 41: the diameter profile and Young's modulus's inputs (issue 22), and the corrected snooker move
# every sampler uses (a wrong Hastings factor changes every posterior)
TARGETS["width"] = ("bayesrod/vision/width.py", ["tests/test_width.py", "tests/test_width_frame.py"], None)
# one frame's measurement alone (session 42: its window, edges, flags and the fixed frames' numbers)
TARGETS["width_frame"] = (
    "bayesrod/vision/width.py",
    ["tests/test_width.py", "tests/test_width_frame.py"],
    ["bayesrod.vision.width.x_width_profile__mutmut_*"],
)
# the frames combined, with the resolution term of a thin stem (session 42)
TARGETS["width_combine"] = (
    "bayesrod/vision/width.py",
    ["tests/test_width.py", "tests/test_width_frame.py"],
    ["bayesrod.vision.width.x_combine_profiles__mutmut_*", "bayesrod.vision.width.x_thin_scale_sd__mutmut_*"],
)
# the colour model, the contrast fit and the profile's records, everything of width.py the two above leave out
# (session 51; session 41's whole-file run left 33 + 18 + 14 + 28 survivors in the colour model's four functions,
# 13 + 15 + 16 in the contrast fit's three, on test_width.py alone)
TARGETS["width_colour"] = (
    "bayesrod/vision/width.py",
    ["tests/test_width.py", "tests/test_width_frame.py"],
    [
        f"bayesrod.vision.width.{f}__mutmut_*"
        for f in [
            f"x_{g}"
            for g in (
                "choose_colour_model",
                "colour_verdict",
                "_cosine",
                "_wide_colours",
                "_purest_pixel",
                "contrast_scale",
                "contrast_fit",
                "contrast_profiles",
                "_box_fit",
                "_blurred_box",
                "_coverage_integrals",
                "_clean_profiles",
                "_robust_poly",
                "_on",
                "_touches",
                "_sample",
                "blur_scale_sd",
                "lens_scale_sd",
                "contrast_fit_scale_sd",
                "variant_scale_sd",
                "frame_scale_sd",
                "_off_profile",
                "_median_sd",
                "_independent_frames",
            )
        ]
        + ["xǁColourChoiceǁto_dict", "xǁDiameterProfileǁto_diameters", "xǁDiameterProfileǁcolumns"]
    ],
)
# the contrast fit's two variants near its switch and the scale sd they declare (session 63; these functions are
# in width_colour as well: a narrow rerun of what that session changed)
TARGETS["width_variant"] = (
    "bayesrod/vision/width.py",
    ["tests/test_width.py", "tests/test_width_frame.py"],
    [
        f"bayesrod.vision.width.x_{g}__mutmut_*"
        for g in ("contrast_fit", "contrast_profiles", "variant_scale_sd", "contrast_fit_scale_sd", "frame_scale_sd")
    ],
)
TARGETS["moves"] = ("bayesrod/inference/moves.py", ["tests/test_moves.py"], None)

# added in session 74: session 72's force levels down a plateau, their spacing and end slope, and the p window with
# its check between p nodes (hand mutants only until then: docs/results/hand_mutants_session72/)
TARGETS["plateau_levels"] = (
    "bayesrod/inference/likelihood.py",
    [
        *(
            f"tests/test_likelihood_core.py::{t}"
            for t in (
                "test_force_levels_cluster_at_the_end_and_go_down_a_plateau",
                "test_a_force_curve_reads_exact_solves_to_its_end_also_on_a_plateau",
                "test_force_levels_closer_than_the_gap_are_dropped_but_the_end_is_kept",
                "test_the_end_slope_is_the_quadratic_through_the_levels_near_the_end_or_the_spline_with_fewer_than_five",
                "test_friction_end_slopes_are_smooth_in_p",
            )
        ),
        *(
            f"tests/test_inference.py::{t}"
            for t in (
                "test_p_zoom_window_narrows_only_a_coarse_p_grid_and_stays_inside_it",
                "test_zoom_window_narrows_only_a_coarse_axis_and_stays_inside_it",
                "test_an_effect_axis_maps_its_coordinate_back_to_the_effect",  # between_nodes at the grid's ends
                "test_a_p_window_is_checked_and_narrows_the_grid_and_the_support",
                "test_the_between_p_nodes_check_moves_only_p_to_the_middle_of_its_node_interval",
                "test_a_start_on_a_p_node_is_checked_between_p_nodes_and_the_worse_decides",
            )
        ),
    ],
    [
        *(
            f"*.x_{f}__mutmut_*"
            for f in ("force_levels", "_spaced", "_end_slope", "_window", "p_zoom_window", "between_nodes")
        ),
    ],
)
TARGETS["p_zoom"] = (
    "bayesrod/api/fitting.py",
    [
        "tests/test_zoom_units.py",
        *(
            f"tests/test_inference.py::{t}"
            for t in (
                "test_the_between_p_nodes_check_moves_only_p_to_the_middle_of_its_node_interval",
                "test_a_start_on_a_p_node_is_checked_between_p_nodes_and_the_worse_decides",
                "test_a_fit_narrows_a_coarse_p_grid_around_its_start",
                "test_a_fit_narrows_a_coarse_effect_axis_around_its_start",
            )
        ),
    ],
    [*(f"*.x_{f}__mutmut_*" for f in ("_check_between_p_nodes", "zoom_decision", "_zoom_tables", "_zoom_edge"))],
)

STATUSES = ("killed", "timeout", "survived", "no tests", "suspicious", "skipped", "segfault")


def classify(diff: list[str]) -> str:
    """Why a surviving mutant cannot change a number, where that is mechanical to see; else "open".

    ``dtype``: only a ``dtype=float`` argument was dropped or set to None (np.asarray of the float arrays that
    reach these functions is the same array either way); ``message``: only the text of a string (an error
    message or a warning filter's text) changed."""
    minus = [ln[1:] for ln in diff if ln.startswith("-")]
    plus = [ln[1:] for ln in diff if ln.startswith("+")]
    if len(minus) != len(plus) or not minus:
        return "open"

    def no_dtype(line: str) -> str:
        return re.sub(r",\s*(dtype=)?(float|None)?\s*\)", ")", line)

    def no_strings(line: str) -> str:
        return re.sub(r"(\"[^\"]*\"|'[^']*')", '""', line)

    pairs = list(zip(minus, plus, strict=True))
    if all("np.asarray(" in a and no_dtype(a) == no_dtype(b) for a, b in pairs):
        return "dtype"
    if all(no_strings(a) == no_strings(b) for a, b in pairs):
        return "message"
    return "open"


def _tracked() -> list[str]:
    return subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()


def _stale(dest: Path) -> bool:
    """Whether a working copy left by an earlier run differs from the checkout (its results would be
    for other code: it is copied again, and mutmut starts over)."""
    mutmut_config = {"pyproject.toml"}  # _configure appends mutmut's section to the copy
    return any(
        f not in mutmut_config and (not (dest / f).exists() or (dest / f).read_bytes() != (ROOT / f).read_bytes())
        for f in _tracked()
        if (ROOT / f).is_file()
    )


def _copy_tree(dest: Path) -> None:
    for f in _tracked():
        target = dest / f
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / f, target)


def _configure(dest: Path, module: str, tests: list[str]) -> None:
    cfg = (
        "\n[tool.mutmut]\n"
        'source_paths = ["bayesrod"]\n'
        f'only_mutate = ["{module}"]\n'
        # data files some tests read from the checkout (the SBC's prior, the prior folder, the documented defaults)
        'also_copy = ["scripts", "priors", "docs"]\n'
        # one process per mutant run (the default addopts ask xdist for 2), no cache writes
        'pytest_add_cli_args = ["-n0", "-p", "no:cacheprovider"]\n'
        f"pytest_add_cli_args_test_selection = {json.dumps(tests)}\n"
    )
    py = dest / "pyproject.toml"
    text = py.read_text()
    if "[tool.mutmut]" not in text:
        py.write_text(text + cfg)


def _mutmut(dest: Path, *args: str, log=None) -> str:
    # BAYESROD_NO_JIT: the numpy step a mutant of elastica.py changes is the one the tests run (the compiled loop,
    # not mutated, is held to it by tests/test_elastica.py), as in the runs before the loop existed
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "BAYESROD_NO_JIT": "1"}
    res = subprocess.run(
        [sys.executable, "-m", "mutmut", *args],
        cwd=dest,
        env=env,
        stdout=log or subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    return "" if log else res.stdout


def _statuses(dest: Path, patterns: list[str] | None) -> dict[str, str]:
    """mutmut's status of every mutant of the target (its function patterns) in the working copy ``dest``."""
    status: dict[str, str] = {}
    for line in _mutmut(dest, "results", "--all", "true").splitlines():
        key, _, value = line.strip().rpartition(": ")
        if key.startswith("bayesrod.") and (patterns is None or any(fnmatch(key, pat) for pat in patterns)):
            status[key] = value
    return status


def run_target(name: str, work: Path, workers: int, sample: int | None = None, seed: int = 0) -> dict:
    """Run one target; ``sample``: only that many of its mutants, drawn at random with ``seed`` (a long target's
    score as an estimate: its binomial sd is sqrt(s (1 - s) / sample))."""
    module, tests, patterns = TARGETS[name]
    dest = work / name
    if dest.exists() and _stale(dest):
        print(f"  {dest} holds other code than the checkout: copied again", flush=True)
        shutil.rmtree(dest)
    if not dest.exists():
        _copy_tree(dest)
    _configure(dest, module, tests)
    t0 = time.perf_counter()
    drawn = None  # the sample's size, population and seed
    with open(dest / "mutmut.log", "w") as log:
        chosen = patterns or []
        if sample:
            # generate the mutants (and run the clean and stats passes) without testing any: a name none has
            _mutmut(dest, "run", "--max-children", str(workers), "bayesrod.no_such_function__mutmut_0", log=log)
            every = sorted(_statuses(dest, patterns))
            chosen = sorted(np.random.default_rng(seed).choice(every, min(sample, len(every)), replace=False).tolist())
            drawn = {"size": len(chosen), "of": len(every), "seed": seed}
        _mutmut(dest, "run", "--max-children", str(workers), *chosen, log=log)
    seconds = time.perf_counter() - t0
    status = _statuses(dest, patterns)
    if drawn:
        status = {k: status[k] for k in chosen}
    counts = {s: sum(v == s for v in status.values()) for s in STATUSES}
    killed = counts["killed"] + counts["timeout"]
    tried = killed + counts["survived"] + counts["no tests"] + counts["suspicious"] + counts["segfault"]
    survivors = {}
    for key, value in status.items():
        if value in ("survived", "no tests", "suspicious"):
            diff = _mutmut(dest, "show", key)
            lines = [ln for ln in diff.splitlines() if ln[:1] in "+-" and not ln.startswith(("+++", "---"))]
            survivors[key] = {
                "status": value,
                "class": classify(lines) if value == "survived" else value,
                "diff": lines,
            }
    return {
        "module": module,
        "functions": patterns or "all",
        "sample": drawn,
        "tests": tests,
        "counts": counts,
        "tried": tried,
        "killed": killed,
        "score": killed / tried if tried else float("nan"),
        "seconds": seconds,
        "survivors": survivors,
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", choices=sorted(TARGETS), help="targets to run (default: all)")
    ap.add_argument("--work", type=Path, default=Path("/tmp/bayesrod-mutation"), help="working copies")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "mutation.json")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--reclassify", action="store_true", help="only classify the survivors in --out again")
    ap.add_argument("--sample", type=int, help="run only this many of each target's mutants, drawn at random")
    ap.add_argument("--seed", type=int, default=0, help="the random draw of --sample")
    args = ap.parse_args(argv)
    # by its metadata: `python -m mutmut --version` reads a configuration and fails outside a project with one
    try:
        from importlib.metadata import version

        version("mutmut")
    except ImportError:
        raise SystemExit("mutmut is not installed: pip install mutmut==3.8.1") from None
    old = json.loads(args.out.read_text()) if args.out.exists() else {}
    results = dict(old)
    for name in [] if args.reclassify else args.only or list(TARGETS):
        print(f"{name}: mutating {TARGETS[name][0]} ...", flush=True)
        results[name] = run_target(name, args.work, args.workers, args.sample, args.seed)
        r = results[name]
        left = len(r["survivors"])
        print(f"  {r['killed']}/{r['tried']} killed ({100 * r['score']:.1f}%), {left} left, {r['seconds']:.0f} s")
        _write(results, args.out)  # after every target: an interrupted run keeps what it finished
    _write(results, args.out)
    print(f"\n{'target':10s} {'tried':>6s} {'killed':>7s} {'survived':>9s} {'no tests':>9s} {'score':>7s}")
    for name, r in results.items():
        c = r["counts"]
        score = 100 * r["score"]
        print(f"{name:10s} {r['tried']:6d} {r['killed']:7d} {c['survived']:9d} {c['no tests']:9d} {score:6.1f}%")
    print(f"wrote {args.out}")


def _write(results: dict, out: Path) -> None:
    """Classify every survivor (this version of :func:`classify`) and write ``out`` atomically."""
    for r in results.values():
        for s in r["survivors"].values():
            s["class"] = classify(s["diff"]) if s["status"] == "survived" else s["status"]
        r["classes"] = {c: sum(s["class"] == c for s in r["survivors"].values()) for c in ("dtype", "message", "open")}
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(results, indent=1) + "\n")
    tmp.replace(out)


if __name__ == "__main__":
    main()
