// `demcal diagnose`: residual of a calibration -> the physical effect the model lacks -> the model
// extended, with the error before and after (diagnose.hpp).
#include "command_registry.hpp"

#include "demcal/pipelines/campaign.hpp"
#include "demcal/pipelines/diagnose.hpp"

#include <iostream>
#include <memory>
#include <sstream>

namespace demcal::cli::diagnose_command {

// The options' defaults are DiagnoseOptions' own; the text flags are split into names in run().
struct DiagnoseFlags {
  demcal::pipelines::DiagnoseOptions options;
  std::string campaign_file;
  std::string effects = "all";
  std::string held_out;
  bool no_report = false, quiet = false, no_bounds = false, no_removal_check = false,
       no_tentative_effect = false;
};

// Names separated by commas, each trimmed of spaces; "all" or "" = none (every effect, for
// --effects). A list that names nothing (",") is an error naming the flag.
std::vector<std::string> split_names(const std::string& text, const std::string& flag) {
  std::vector<std::string> names;
  if (text == "all" || text.empty()) return names;
  std::stringstream s(text);
  for (std::string name; std::getline(s, name, ',');) {
    const auto first = name.find_first_not_of(" \t");
    if (first == std::string::npos) continue;
    names.push_back(name.substr(first, name.find_last_not_of(" \t") - first + 1));
  }
  if (names.empty()) throw demcal::pipelines::CampaignError(flag + " '" + text + "' names nothing (names separated by commas)");
  return names;
}

void run(const DiagnoseFlags& f) {
  using namespace demcal::pipelines;
  const CampaignConfig config = load_campaign(f.campaign_file);
  DiagnoseOptions o = f.options;
  o.effects = split_names(f.effects, "--effects");
  o.held_out = split_names(f.held_out, "--held-out");
  o.report = !f.no_report;
  o.parameter_bounds = !f.no_bounds;
  o.removal_check = !f.no_removal_check;
  o.tentative_effect = !f.no_tentative_effect;
  o.progress = !f.quiet;
  const Diagnosis d = run_diagnosis(config, o);
  std::cout << d.headline << "\n  - " << d.conclusion << "\n";
  for (const auto& note : d.notes) std::cout << "  - " << note << "\n";
  std::cout << "error before " << d.error_before << " N, after " << d.error_after << " N; " << d.simulations
            << " simulations";
  if (d.simulated_this_session != d.simulations)
    std::cout << " (" << d.simulated_this_session << " run now, " << d.simulations - d.simulated_this_session
              << " read from the archive)";
  std::cout << "\n";
  std::cout << "diagnosis: " << o.out << "/diagnosis.json\n";
}

void setup(CLI::App& app) {
  auto flags = std::make_shared<DiagnoseFlags>();
  auto* sub = app.add_subcommand("diagnose", "Trace a calibration's residual to the physical effect the model lacks");
  sub->add_option("campaign", flags->campaign_file, "Campaign JSON file (as for calibrate)")->required()->check(CLI::ExistingFile);
  auto& o = flags->options;
  sub->add_option("--out", o.out, "Output folder (diagnosis.json, report.md, base/, candidates/)");
  sub->add_option("--effects", flags->effects, "all, or effect names separated by commas (joint-closure,friction-softening,...)");
  sub->add_option("--result", o.result, "Reuse a finished base calibration (its folder or result.json)");
  sub->add_option("--held-out", flags->held_out,
                  "Cases of the campaign, separated by commas, left out of every fit and used to check the fits");
  sub->add_option("--held-out-ratio", o.held_out_ratio,
                  "Held-out channels check the fits where the base fit's RMS is at most this many times their noise")->capture_default_str();
  sub->add_option("--max-simulations", o.max_simulations, "Budget of the whole diagnosis (0 = the campaign's per calibration)");
  auto* candidates =
      sub->add_option("--candidates", o.candidates, "Effects calibrated at most, best signature first")->capture_default_str();
  auto* at_split = sub->add_option("--candidates-at-split", o.candidates_at_split,
                                   "Effects calibrated at most where the base fit's re-runs scatter by more than the noise "
                                   "(0 = every effect; default: every effect, or --candidates when given)");
  sub->add_option("--candidate-simulations", o.candidate_simulations,
                  "Simulations per candidate calibration and for the base refinement (0 = the campaign's)")
      ->capture_default_str();
  sub->add_option("--continued-simulations", o.continued_simulations,
                  "Simulations of a further search for an accepted effect whose fit stays above the noise and scatter, "
                  "then, while no fit explains the curves, for each contender, and for the pair search's calibrated pair "
                  "(-1 = a candidate's budget, 0 = none)")
      ->capture_default_str();
  sub->add_option("--union-rounds", o.union_rounds,
                  "Rounds of the union search after the candidates' calibrations: one emulator of the curves over "
                  "the base and every candidate's parameters, each round simulating its best point for each "
                  "candidate, more where the workers outnumber the candidates (0 = none)")
      ->capture_default_str();
  sub->add_option("--pair-rounds", o.pair_rounds,
                  "Rounds of the pair search where no effect passes alone and the base misses the curves: the "
                  "union search's emulator searched with both effects of a pair switched on, each round simulating "
                  "its best point for each pair near the pair's best run; the closest pair is then calibrated "
                  "(0 = none)")
      ->capture_default_str();
  sub->add_option("--candidate-starts", o.candidate_starts,
                  "Points of each candidate's search design that start from a base fit: the best, then the best "
                  "base sets of other regions")
      ->capture_default_str();
  sub->add_option("--candidate-algorithm", o.candidate_algorithm,
                  "Optimiser of each candidate: bo (default), nlopt:NAME (local, warm-started) or tbpso | pso | ga");
  sub->add_option("--surrogate-kind", o.surrogate_kind, "Surrogate of the refinement's and candidates' searches: gp | mlp")
      ->capture_default_str()
      ->check(CLI::IsMember({"gp", "mlp"}));
  sub->add_option("--surrogate-backend", o.surrogate_backend,
                  "Training of the mlp surrogate in every calibration of the diagnosis: libtorch | native")
      ->capture_default_str()
      ->check(CLI::IsMember({"libtorch", "native"}));
  sub->add_option("--evidence", o.evidence, "Criterion fall needed to accept an effect")->capture_default_str();
  sub->add_option("--tie-margin", o.tie_margin,
                  "Effects whose criteria are closer than this are tied (the data cannot tell them apart)")
      ->capture_default_str();
  sub->add_option("--close-target-share", o.close_target_share,
                  "Other targets of an effect (joints, supports) calibrated too when their signature explains at least "
                  "this share of the best target's; the better fit is kept (1 = the best target only)")
      ->capture_default_str();
  sub->add_option("--close-candidate-share", o.close_candidate_share,
                  "Effects ranked below the --candidates tried are calibrated too when their signature explains at "
                  "least this share of the last one tried's (1 = only an exact tie)")
      ->capture_default_str();
  sub->add_option("--scatter-runs", o.scatter_runs,
                  "Re-runs of the base best, parameters moved by 1e-7, that measure the simulation's own scatter (0 = none)")->capture_default_str();
  sub->add_option("--scatter-floor-ratio", o.scatter_floor_ratio,
                  "The scatter counts in the error floor up to this x the noise (inf = all of it)")
      ->capture_default_str();
  sub->add_flag("--resume", o.resume, "Continue interrupted calibrations from their archives");
  sub->add_flag("--no-report", flags->no_report, "Skip report.md and figures");
  sub->add_flag("--no-parameter-bounds", flags->no_bounds,
                "Skip the check of how tightly the data pin an accepted effect's parameters (4 runs each, and re-fits)");
  sub->add_option("--profile-simulations", o.profile_simulations,
                  "Runs per re-fit of the other parameters at a value the bounds' check rules out (0 = no re-fit)")
      ->capture_default_str();
  sub->add_flag("--no-removal-check", flags->no_removal_check,
                "Skip the removal check: each effect added re-fitted without (the base alone for one), and dropped when that costs no evidence or leaves the fit explained");
  sub->add_flag("--no-tentative-effect", flags->no_tentative_effect,
                "Where no effect passes alone, do not add the best one tentatively to look for a second that passes with it");
  sub->add_option("--max-effects", o.max_effects,
                  "Effects added at most: after one is accepted the model with it is diagnosed again, until none passes (0 = no limit)")
      ->capture_default_str();
  sub->add_option("--resamples", o.resamples,
                  "Resamples of the data and of the fits' round-off on which the selection is taken again (0 = none)")
      ->capture_default_str();
  sub->add_option("--verdict-share", o.verdict_share,
                  "A choice reached in fewer than this share of the resamples is not the verdict: undecided")
      ->capture_default_str();
  sub->add_flag("--quiet", flags->quiet, "No progress lines");
  sub->callback([flags, candidates, at_split] {
    // an explicit --candidates caps a split base too, unless --candidates-at-split says otherwise
    if (candidates->count() > 0 && at_split->count() == 0) flags->options.candidates_at_split = flags->options.candidates;
    run(*flags);
  });
}

}  // namespace demcal::cli::diagnose_command

DEMCAL_REGISTER_COMMAND("diagnose", demcal::cli::diagnose_command::setup);
