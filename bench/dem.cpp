// Engine speed: the reference arch at the paper's calibration rate, the verification rate and the
// experiment's own rate (with density scaling), and a dry-joint wall. Counters: simulated steps
// per second and contact-node updates per second.
//   build/bench/bench_dem --benchmark_filter=...
#include "demcal/dem/effects.hpp"
#include "demcal/dem/generators.hpp"
#include "demcal/dem/simulation.hpp"

#include <benchmark/benchmark.h>

namespace {

using namespace demcal::dem;

// Times simulate(scene); a run that does not complete is an error unless `any_status` (an effect
// may end a run early, and its cost is still the figure).
void run_scene(benchmark::State& state, const Scene& scene, bool any_status = false) {
  long steps = 0, updates = 0;
  double peak = 0;
  for (auto _ : state) {
    const Recording r = simulate(scene);
    if (!any_status && r.status != RunStatus::completed) state.SkipWithError(r.message.c_str());
    steps += r.steps;
    updates += r.contact_point_updates;
    peak = r.peak_force;
  }
  state.counters["steps_per_s"] = benchmark::Counter(static_cast<double>(steps), benchmark::Counter::kIsRate);
  state.counters["node_updates_per_s"] = benchmark::Counter(static_cast<double>(updates), benchmark::Counter::kIsRate);
  state.counters["steps"] = static_cast<double>(steps) / state.iterations();
  state.counters["peak_N"] = peak;
}

// The benchmark argument `faces`: 0 = the automatic step over every face (`time_step_faces` "all",
// the engine's earlier default), 1 = over the faces in contact ("in_contact", the default).
Scene with_step_faces(Scene scene, benchmark::State& state, std::int64_t faces) {
  scene.solver.time_step_faces = faces == 0 ? "all" : "in_contact";
  state.SetLabel("time_step_faces " + scene.solver.time_step_faces);
  return scene;
}

void ReferenceArch_10mm_per_s(benchmark::State& state) {
  ArchOptions o;
  o.contacts_per_joint = static_cast<int>(state.range(0));
  run_scene(state, with_step_faces(make_arch(o), state, state.range(1)));
}
BENCHMARK(ReferenceArch_10mm_per_s)->ArgsProduct({{15, 5}, {0, 1}})->Unit(benchmark::kMillisecond);

void ReferenceArch_0p5mm_per_s(benchmark::State& state) {
  ArchOptions o;
  o.velocity = 0.0005;
  run_scene(state, make_arch(o));
}
BENCHMARK(ReferenceArch_0p5mm_per_s)->Unit(benchmark::kMillisecond)->Iterations(2);

// The experiment's 0.005 mm/s (2400 s of loading) with inertia scaled by range(0).
void ReferenceArch_0p005mm_per_s_scaled(benchmark::State& state) {
  ArchOptions o;
  o.velocity = 5e-6;
  Scene s = make_arch(o);
  s.solver.density_scaling = static_cast<double>(state.range(0));
  run_scene(state, s);
}
BENCHMARK(ReferenceArch_0p005mm_per_s_scaled)->Arg(400)->Unit(benchmark::kSecond)->Iterations(1);

void Wall_SW30_2mm_travel(benchmark::State& state) {
  WallOptions o;
  o.max_displacement = 0.002;
  run_scene(state, with_step_faces(make_wall(o), state, state.range(0)));
}
BENCHMARK(Wall_SW30_2mm_travel)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(2);

// SW.30.1 at the wall campaigns' settings (docs/walls.md): 20 mm/s, 5 points per joint, 33 mm of
// travel, with its calibrated joints (kn 4.31 GPa/m, ks 0.58 GPa/m, friction 30.1 deg).
void Wall_SW30_campaign(benchmark::State& state) {
  WallOptions o;
  o.kn = 4.31e9;
  o.ks = 0.58e9;
  o.friction_deg = 30.1;
  o.contacts_per_joint = 5;
  o.velocity = 0.02;
  o.max_displacement = 0.033;
  run_scene(state, with_step_faces(make_wall(o), state, state.range(0)));
}
BENCHMARK(Wall_SW30_campaign)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(2);

// The reference arch (15 points/joint, 10 mm/s) with one effect of the registry switched on at its
// default values; range(0) indexes effect_registry(). Compare with ReferenceArch_10mm_per_s/15.
void ReferenceArch_effect(benchmark::State& state) {
  const Effect& effect = effect_registry().at(static_cast<std::size_t>(state.range(0)));
  Scene s = make_arch(ArchOptions{});
  std::vector<std::string> targets;
  if (effect.target == EffectTarget::joint) targets = {"voussoir_9/voussoir_10"};
  enable_effect(s, effect.name, targets);
  state.SetLabel(effect.name);
  run_scene(state, s, /*any_status=*/true);
}
BENCHMARK(ReferenceArch_effect)
    ->DenseRange(0, static_cast<int>(effect_registry().size()) - 1)
    ->Unit(benchmark::kMillisecond);

// The same for an effect whose tangent stiffness grows, with time_step_stiffening "nodes" (the step
// follows the touching nodes' stiffening) instead of the default "caps".
void ReferenceArch_effect_step_follows_nodes(benchmark::State& state, const char* effect) {
  Scene s = make_arch(ArchOptions{});
  enable_effect(s, effect, {});
  s.solver.time_step_stiffening = "nodes";
  state.SetLabel(std::string(effect) + ", time_step_stiffening nodes");
  run_scene(state, s, /*any_status=*/true);
}
BENCHMARK_CAPTURE(ReferenceArch_effect_step_follows_nodes, joint_closure, "joint-closure")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(ReferenceArch_effect_step_follows_nodes, shear_stiffening, "shear-stiffening")
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
