// avp bench: scenarios x planners x seeds in parallel, with summary tables and plots.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <avp/core/text.h>
#include <avp/eval/statistics.h>
#include <avp/experiment/bench.h>
#include <avp/report/conditions.h>

#include "cli_common.h"
#include "run_cli.h"

namespace avp::apps {

namespace {

struct BenchCli {
  std::string config, scenarios, planners, seeds, seed, conditions, shard, out = "out/bench";
  EpisodeFlags episode;
  int jobs = 0;
  bool force = false, resume = false, record = false;
  std::string record_compression;
  std::vector<std::string> planner_options;
};

/// --seeds: "N" for 0..N-1 (N >= 1), or a list "0,1,5" (no empty item); --seed (`count` false):
/// the seeds themselves, "5" is seed 5. InvalidArgument naming the text otherwise; at most
/// kMaxBenchSeeds seeds, checked before the list is made.
Result<std::vector<uint64_t>> ParseSeeds(const std::string& text, bool count) {
  const char* option = count ? "--seeds" : "--seed";
  AVP_ASSIGN_OR_RETURN(const std::vector<std::string> items,
                       ParseCliList(option, text, experiment::kMaxBenchSeeds));
  std::vector<uint64_t> seeds;
  if (count && items.size() == 1 && text.find(',') == std::string::npos) {
    AVP_ASSIGN_OR_RETURN(const uint64_t n,
                         ParseCliUnsigned("--seeds (a count N for seeds 0..N-1)", items[0], 1,
                                          experiment::kMaxBenchSeeds));
    for (uint64_t i = 0; i < n; ++i) seeds.push_back(i);
    return seeds;
  }
  for (const std::string& item : items) {
    AVP_ASSIGN_OR_RETURN(const uint64_t s, ParseCliUnsigned(fmt::format("{}: a seed", option), item,
                                                            0, MaxOf<uint64_t>()));
    seeds.push_back(s);
  }
  return seeds;
}

/// --shard K/N: 1 <= K <= N <= kMaxShards.
constexpr uint64_t kMaxShards = 100000;
Status ParseShard(const std::string& text, experiment::BenchConfig& b) {
  const size_t slash = text.find('/');
  if (slash == std::string::npos) {
    return InvalidArgumentError(
        fmt::format("--shard {} must be K/N (the K-th of N slices, e.g. 2/8)", QuoteText(text)));
  }
  AVP_ASSIGN_OR_RETURN(b.shard_count, ParseCliUnsigned("--shard: the shard count N",
                                                       text.substr(slash + 1), 1, kMaxShards));
  AVP_ASSIGN_OR_RETURN(b.shard_index, ParseCliUnsigned("--shard: the shard K of N",
                                                       text.substr(0, slash), 1, b.shard_count));
  return Status::Ok();
}

/// --planner-option PLANNER:KEY=VALUE (or KEY=VALUE when the bench has one planner).
Status ApplyPlannerOptions(const std::vector<std::string>& items, experiment::BenchConfig& b) {
  for (const std::string& item : items) {
    const size_t colon = item.find(':');
    const size_t eq = item.find('=');
    std::string planner, key_value = item;
    if (colon != std::string::npos && colon < eq) {
      planner = item.substr(0, colon);
      key_value = item.substr(colon + 1);
    } else if (b.planners.size() == 1) {
      planner = b.planners.front();
    } else {
      return InvalidArgumentError(fmt::format(
          "planner option {} must name its planner: PLANNER:KEY=VALUE (e.g. avp-nbv:{})",
          QuoteText(item), EscapeText(item)));
    }
    AVP_ASSIGN_OR_RETURN(const OptionValues values, ParseKeyValues({key_value}, "planner option"));
    for (const auto& kv : values) b.planner_options[planner].push_back(kv);
  }
  return Status::Ok();
}

/// The bench of the command line: --config (or the defaults), then the flags given.
Result<experiment::BenchConfig> ResolveBench(const CLI::App& cmd, const BenchCli& cli,
                                             const experiment::Registries& registries) {
  experiment::BenchConfig b;
  if (!cli.config.empty()) {
    AVP_ASSIGN_OR_RETURN(b, experiment::LoadBenchConfig(cli.config));
  }
  // A list given on the command line is used as given: an empty one is an error, never "the
  // defaults" (those apply only when neither the option nor --config names the list).
  if (cmd.get_option("--scenarios")->count() > 0) {
    AVP_ASSIGN_OR_RETURN(b.scenarios, ParseCliList("--scenarios", cli.scenarios));
  }
  if (cmd.get_option("--planners")->count() > 0) {
    AVP_ASSIGN_OR_RETURN(b.planners, ParseCliList("--planners", cli.planners));
  }
  if (cmd.get_option("--seeds")->count() > 0 && cmd.get_option("--seed")->count() > 0) {
    return InvalidArgumentError(
        "--seeds and --seed both given: --seeds N runs seeds 0..N-1, --seed S,T runs those seeds; "
        "give one");
  }
  if (cmd.get_option("--seeds")->count() > 0) {
    AVP_ASSIGN_OR_RETURN(b.seeds, ParseSeeds(cli.seeds, true));
  }
  if (cmd.get_option("--seed")->count() > 0) {
    AVP_ASSIGN_OR_RETURN(b.seeds, ParseSeeds(cli.seed, false));
  }
  if (cli.config.empty()) experiment::FillBenchDefaults(b, registries);
  AVP_RETURN_IF_ERROR(ApplyPlannerOptions(cli.planner_options, b));
  AVP_RETURN_IF_ERROR(ApplyEpisodeFlags(cmd, cli.episode, b.base));
  b.jobs = cli.jobs;
  b.out_dir = cli.out;
  b.force = cli.force;
  b.resume = cli.resume;
  if (cmd.get_option("--shard")->count() > 0) AVP_RETURN_IF_ERROR(ParseShard(cli.shard, b));
  b.record = cli.record;
  b.record_compression = cli.record_compression;
  if (cmd.get_option("--conditions")->count() > 0) {
    AVP_ASSIGN_OR_RETURN(const std::vector<std::string> names,
                         ParseCliList("--conditions", cli.conditions));
    std::vector<experiment::BenchCondition> chosen;
    std::vector<std::string> known;
    for (const experiment::BenchCondition& c : b.conditions) known.push_back(c.name);
    for (const std::string& name : names) {
      const auto it = std::find_if(b.conditions.begin(), b.conditions.end(),
                                   [&](const auto& c) { return c.name == name; });
      if (it == b.conditions.end()) {
        return InvalidArgumentError(fmt::format(
            "--conditions: {} is not a condition of the configuration ({})", QuoteText(name),
            known.empty() ? std::string("it has none")
                          : fmt::format("{}", fmt::join(known, ", "))));
      }
      chosen.push_back(*it);
    }
    b.conditions = std::move(chosen);
  }
  if (!cli.config.empty()) b.inputs.emplace_back(cli.config, "bench configuration file");
  return b;
}

void PrintBench(const std::filesystem::path& out_dir, const experiment::BenchSummary& s) {
  std::printf(
      "%zu episode%s (%zu failed) in %.1f s. Final view, mean over the seeds [95 %% interval]:\n",
      s.episodes, s.episodes == 1 ? "" : "s", s.failed, s.seconds);
  size_t scenario_w = 8, planner_w = 7;
  for (const auto& c : s.cells) {
    scenario_w = std::max(scenario_w, c.scenario.size());
    planner_w = std::max(planner_w, c.planner.size());
  }
  std::printf("  %-*s  %-*s  %-4s  %-30s  %-30s  %s\n", static_cast<int>(scenario_w), "scenario",
              static_cast<int>(planner_w), "planner", "n", "F1 (exact)", "fraction found",
              "plan ms/step");
  for (const auto& c : s.cells) {
    std::printf(
        "  %-*s  %-*s  %-4zu  %-30s  %-30s  %.0f\n", static_cast<int>(scenario_w),
        c.scenario.c_str(), static_cast<int>(planner_w), c.planner.c_str(), c.runs,
        eval::FormatMeanInterval(c.final_f1_mean, c.final_f1_lo, c.final_f1_hi, c.runs).c_str(),
        eval::FormatMeanInterval(c.final_found_mean, c.final_found_lo, c.final_found_hi, c.runs)
            .c_str(),
        c.plan_ms_mean);
  }
  if (!s.leads.empty()) {
    std::printf(
        "Lead of %s, paired by seed (its final F1 minus the other's, mean [95 %% interval]):\n",
        s.leads.front().planner.c_str());
    for (const report::PairedLead& l : s.leads) {
      std::printf("  %-*s  vs %-*s  %-34s  %s\n", static_cast<int>(scenario_w), l.scenario.c_str(),
                  static_cast<int>(planner_w), l.versus.c_str(),
                  eval::FormatMeanInterval(l.f1, 3, true).c_str(), l.verdict.c_str());
    }
  }
  std::printf("wrote %s and the per-run records under %s\n", s.files.front().string().c_str(),
              (out_dir / "runs").string().c_str());
  if (!s.report_html.empty()) std::printf("report: %s\n", s.report_html.string().c_str());
}

/// The lead planner's paired differences, one line each, and where the tables are.
void PrintConditions(const report::ConditionTables& t) {
  std::printf("Lead over each planner, final F1, paired by seed (mean [95 %% interval]):\n");
  for (const report::ConditionLead& l : t.leads) {
    std::printf("  %-22s %-28s %s vs %-14s %-34s  %s\n", l.condition.c_str(), l.scenario.c_str(),
                l.planner.c_str(), l.versus.c_str(),
                eval::FormatMeanInterval(l.f1, 3, true).c_str(), l.verdict.c_str());
  }
  std::printf("wrote %s and %s\n", t.files.at(0).string().c_str(), t.files.at(1).string().c_str());
}

/// Failed episodes are left out of the statistics; the command says so and fails (0: none).
int FailedEpisodes(size_t failed, size_t episodes) {
  if (failed == 0) return 0;
  return Failed("bench", UnavailableError(fmt::format(
                             "{} of {} episodes failed (each run folder's avp-state.json or "
                             "record.json says why)",
                             failed, episodes)));
}

int BenchConditions(const experiment::BenchConfig& bench,
                    const experiment::Registries& registries) {
  const Result<experiment::ConditionsSummary> summary =
      experiment::RunBenchConditions(bench, registries);
  if (!summary.ok()) return Failed("bench", summary.status());
  std::printf("%zu conditions, %zu episodes (%zu failed) in %.1f s.\n", summary->benches.size(),
              summary->episodes, summary->failed, summary->seconds);
  PrintConditions(summary->tables);
  return FailedEpisodes(summary->failed, summary->episodes);
}

int Bench(const CLI::App& cmd, const BenchCli& cli, const experiment::Registries& registries) {
  // `help` wherever a name is expected, as `avp run --planner help`.
  if (int code = 0;
      PrintHelpForNames(registries, cli.scenarios, cli.planners, cli.episode.segmenter, &code)) {
    return code;
  }
  const Result<experiment::BenchConfig> bench = ResolveBench(cmd, cli, registries);
  if (!bench.ok()) return Failed("bench", bench.status());
  if (!bench->conditions.empty()) return BenchConditions(*bench, registries);
  const Result<experiment::BenchSummary> summary = experiment::RunBench(*bench, registries);
  if (!summary.ok()) return Failed("bench", summary.status());
  if (summary->resumed > 0) {
    std::printf("resumed: %zu of the episodes were complete and read back, not run again\n",
                summary->resumed);
  }
  if (bench->shard_count > 1) {
    std::printf(
        "shard %llu/%llu: %zu episodes (%zu failed) in %.1f s under %s; merge the shards with "
        "avp bench merge SHARD_DIR... --out DIR\n",
        static_cast<unsigned long long>(bench->shard_index),
        static_cast<unsigned long long>(bench->shard_count), summary->episodes, summary->failed,
        summary->seconds, bench->out_dir.string().c_str());
    return FailedEpisodes(summary->failed, summary->episodes);
  }
  PrintBench(bench->out_dir, *summary);
  return FailedEpisodes(summary->failed, summary->episodes);
}

struct MergeCli {
  std::vector<std::string> dirs;
  std::string out;
  bool force = false;
};

/// avp bench merge SHARD_DIR... --out D: the shards of one bench as one bench folder.
int Merge(const MergeCli& cli) {
  std::vector<std::filesystem::path> dirs(cli.dirs.begin(), cli.dirs.end());
  const Result<experiment::BenchSummary> s = experiment::MergeBenches(dirs, cli.out, cli.force);
  if (!s.ok()) return Failed("bench merge", s.status());
  std::printf("merged %zu shard folders.\n", dirs.size());
  PrintBench(cli.out, *s);
  return FailedEpisodes(s->failed, s->episodes);
}

struct CompareCli {
  std::vector<std::string> dirs;
  std::string out, lead = "avp-nbv";
};

/// avp bench compare DIR...: the conditions tables of bench folders run apart.
int Compare(const CompareCli& cli) {
  std::vector<report::ConditionBench> benches;
  for (const std::string& d : cli.dirs) {
    const std::filesystem::path dir = std::filesystem::path(d).lexically_normal();
    std::string name = dir.filename().string();
    if (name.empty()) name = dir.parent_path().filename().string();
    benches.push_back({name, "", dir});
  }
  const Result<report::ConditionTables> t =
      report::WriteConditionTables(cli.out, benches, cli.lead);
  if (!t.ok()) return Failed("bench compare", t.status());
  PrintConditions(*t);
  return 0;
}

}  // namespace

void AddBenchCommand(CLI::App& app, CommandContext& context) {
  auto cli = std::make_shared<BenchCli>();
  CLI::App* cmd = app.add_subcommand(
      "bench", "Scenarios x planners x seeds in parallel, with summary tables and plots");
  cmd->add_option("--config", cli->config, "Experiment YAML (e.g. configs/experiments/paper.yaml)");
  // avp run's singular spellings are accepted too: --scenario and --planner as aliases, --seed as
  // a list of seeds (never a count).
  cmd->add_option("--scenarios,--scenario", cli->scenarios,
                  "Comma-separated scenarios and scene files (FILE.yaml, relative to the current "
                  "folder), each optionally @ARRANGEMENT (FILE.yaml@paper: the four paper "
                  "arrangements); `help` lists them; overrides the config")
      ->type_name("NAME,...");
  cmd->add_option("--planners,--planner", cli->planners,
                  "Comma-separated planners (overrides the config); `help` lists them")
      ->type_name("NAME,...");
  cmd->add_option("--seeds", cli->seeds,
                  "N for seeds 0..N-1, or comma-separated seeds (overrides the config)")
      ->type_name("N|SEED,...");
  cmd->add_option("--seed", cli->seed, "Comma-separated seeds, \"5\" being seed 5 (not a count)")
      ->type_name("SEED,...");
  AddEpisodeFlags(*cmd, cli->episode);
  AddNumberOption(*cmd, "--jobs", cli->jobs, 0, experiment::kMaxThreads,
                  "Episodes at once (0 = hardware threads)");
  AddKeyValueOption(*cmd, "--planner-option", cli->planner_options,
                    "PLANNER:KEY=VALUE for that planner's episodes (repeatable; KEY=VALUE when "
                    "the bench has one planner); over the config's planner_options");
  cmd->add_option("--out", cli->out, "Output folder")->default_str(cli->out);
  cmd->add_flag("--force", cli->force,
                "Replace the results an earlier bench left in --out (only an avp bench folder)");
  CLI::Option* record =
      cmd->add_flag("--record", cli->record,
                    "Record every episode as MCAP: runs/<scenario>/<planner>/seed-<n>/episode.mcap "
                    "(docs/recording.md)");
  AddRecordCompressionOption(*cmd, cli->record_compression, record);
  cmd->add_option("--shard", cli->shard,
                  "K/N: run only the K-th of N deterministic slices of the job list (jobs dealt "
                  "round-robin); merge the shard folders with avp bench merge (docs/cluster.md)");
  cmd->add_flag("--resume", cli->resume,
                "--out holds an interrupted run of this same bench: keep its complete episodes, "
                "run the others");
  cmd->add_option("--conditions", cli->conditions,
                  "Comma-separated conditions of the config to run (default: all of them)")
      ->type_name("NAME,...");
  auto compare = std::make_shared<CompareCli>();
  CLI::App* compare_cmd = cmd->add_subcommand(
      "compare",
      "Compare bench folders run under different conditions: each planner's final F1 and fruits "
      "found, and the lead planner's paired difference over each other one (conditions.md, "
      "conditions.csv)");
  compare_cmd->add_option("dirs", compare->dirs, "Bench folders; each is named by its folder")
      ->required();
  compare_cmd->add_option("--out", compare->out, "Folder for conditions.md and conditions.csv")
      ->required();
  compare_cmd->add_option("--lead", compare->lead, "The planner compared with the others")
      ->default_str(compare->lead);
  compare_cmd->callback(
      [compare, &context] { RunGuarded(context, [&] { return Compare(*compare); }); });
  auto merge = std::make_shared<MergeCli>();
  CLI::App* merge_cmd = cmd->add_subcommand(
      "merge",
      "Merge the shard folders of one bench (avp bench --shard K/N) into one bench folder: the "
      "runs, summary.md, summary.csv, plots and report.html of a single-machine run");
  merge_cmd->add_option("dirs", merge->dirs, "Shard folders (all N of them)")->required();
  merge_cmd->add_option("--out", merge->out, "The merged bench folder")->required();
  merge_cmd->add_flag("--force", merge->force,
                      "Replace the results an earlier merge or bench left in --out");
  merge_cmd->callback([merge, &context] { RunGuarded(context, [&] { return Merge(*merge); }); });
  cmd->callback([cli, cmd, compare_cmd, merge_cmd, &context] {
    // avp bench compare / merge: their own callbacks ran.
    if (compare_cmd->parsed() || merge_cmd->parsed()) return;
    RunGuarded(context, [&] { return Bench(*cmd, *cli, *context.registries); });
  });
}

}  // namespace avp::apps
