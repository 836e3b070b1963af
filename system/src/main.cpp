#include "prime/system/main.hpp"

#include <signal.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "prime/system/host.hpp"
#include "prime/system/system_file.hpp"

namespace prime::system {

namespace {

std::string shown(const ParamValue& value) {
  return std::visit([](const auto& v) -> std::string {
    using V = std::decay_t<decltype(v)>;
    if constexpr (std::is_same_v<V, bool>) return v ? "true" : "false";
    else if constexpr (std::is_same_v<V, std::string>) return '"' + v + '"';
    else return std::to_string(v);
  }, value);
}

// "integer", of "an integer".
std::string kind(const ParamValue& value) {
  const auto name = param_type_name(value.index());
  return std::string{name.substr(name.find(' ') + 1)};
}

void describe(const Registry& registry) {
  for (const auto* c : registry.components()) {
    std::printf("%s\n", c->type().c_str());
    for (const auto& p : c->ports())
      std::printf("  %-10s %-24s %s%s\n", std::string{to_string(p.kind)}.c_str(), p.name.c_str(), p.message.describe().c_str(),
                  p.reply ? (" -> " + p.reply->describe()).c_str() : "");
    for (const auto& set : c->synced_sets()) {
      std::string topics;
      for (const auto& t : set.topics) topics += (topics.empty() ? "" : " + ") + t;
      std::printf("  syncs      %-24s %s\n", set.name.c_str(), topics.c_str());
    }
    for (const auto& t : c->triggers())
      std::printf("  every      %-24s %lld ms\n", t.name.c_str(), static_cast<long long>(t.period.count()));
    for (const auto& p : c->params())
      std::printf("  param      %-24s %s = %s%s%s\n", p.name.c_str(), kind(p.value).c_str(),
                  shown(p.value).c_str(), p.help.empty() ? "" : "  # ", p.help.c_str());
  }
}

std::string links(const Plan& plan) {
  std::string all;
  for (const auto& [name, reach] : plan.reach) {
    std::string via;
    if (reach & Reach::here) via += "in-process";
    if (reach & Reach::same_machine) via += std::string{via.empty() ? "" : "+"} + "shm";
    if (reach & Reach::other_machine) via += std::string{via.empty() ? "" : "+"} + "redis";
    all += (all.empty() ? "" : ", ") + name + " " + via;
  }
  return all.empty() ? "none" : all;
}

}  // namespace

int run(int argc, char** argv) {
  std::string file, placement, process, domain, ns;
  std::vector<std::string> overrides;
  enum class Mode { none, host, check, describe } mode = Mode::none;
  const auto usage = [&](const std::string& why) {
    std::fprintf(stderr, "%s: %s\nusage: %s --prime-system FILE --placement NAME --process NAME [--param component.name=value]... [--domain D] [--namespace NS]\n"
                         "       %s --prime-check FILE --placement NAME\n       %s --prime-describe\n",
                 argv[0], why.c_str(), argv[0], argv[0], argv[0]);
    return 2;
  };
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const auto value = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    if (arg == "--prime-describe") {
      mode = Mode::describe;
    } else if (arg == "--prime-system" || arg == "--prime-check" || arg == "--placement" || arg == "--process" || arg == "--param" ||
               arg == "--domain" || arg == "--namespace") {
      const char* v = value();
      if (!v) return usage(arg + " needs a value");
      if (arg == "--prime-system" || arg == "--prime-check") {
        file = v;
        mode = arg == "--prime-system" ? Mode::host : Mode::check;
      } else if (arg == "--placement") {
        placement = v;
      } else if (arg == "--process") {
        process = v;
      } else if (arg == "--domain") {
        domain = v;
      } else if (arg == "--namespace") {
        ns = v;
      } else {
        overrides.emplace_back(v);
      }
    } else {
      return usage("unknown argument '" + arg + "'");
    }
  }
  const auto& registry = Registry::global();
  if (mode == Mode::none) return usage("say what to do");
  if (const auto wrong = registry.problems(); !wrong.empty()) {  // PRIME_COMPONENT, as the program started
    for (const auto& w : wrong) std::fprintf(stderr, "%s: %s\n", argv[0], w.c_str());
    return mode == Mode::check ? 1 : 2;
  }
  if (mode == Mode::describe) {
    describe(registry);
    return 0;
  }
  if (placement.empty()) return usage("--placement is needed");
  try {
    auto system = load_system(file, overrides);
    if (!domain.empty()) system.domain = domain;
    if (!ns.empty()) system.ns = ns;
    load_libraries(system);
    if (mode == Mode::check) {
      const auto found = problems(system, registry, placement);
      for (const auto& p : found) std::fprintf(stderr, "%s\n", p.c_str());
      if (!found.empty()) return 1;
      std::string order;
      for (const auto& p : start_order(system, registry, placement)) order += " " + p;
      std::printf("order:%s\n", order.c_str());
      return 0;
    }
    if (process.empty()) return usage("--process is needed");
    // SIGINT and SIGTERM are taken by sigwait below: blocked before any
    // worker starts, so that every thread inherits the mask.
    sigset_t stop_signals;
    sigemptyset(&stop_signals);
    sigaddset(&stop_signals, SIGINT);
    sigaddset(&stop_signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
    // Started by prime launch (it says where to tell it we are ready): a
    // launcher that dies takes its processes with it (SIGTERM, taken below).
    int ready_fd = -1;
    if (const char* fd = std::getenv("PRIME_READY_FD")) {
      char* end = nullptr;
      const long n = std::strtol(fd, &end, 10);
      if (end != fd && *end == '\0' && n > 2 && n < 1024) ready_fd = static_cast<int>(n);
      ::unsetenv("PRIME_READY_FD");  // not for what this process starts
      ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    }
    auto plan = plan_of(system, registry, placement, process);
    std::string hosted;
    for (const auto& i : plan.instances) hosted += (hosted.empty() ? "" : ", ") + i.name + " (" + i.component + ")";
    std::printf("[prime] process '%s' of placement '%s': hosting %s; links: %s%s\n", process.c_str(), placement.c_str(),
                hosted.c_str(), links(plan).c_str(), plan.ns.empty() ? "" : ("; names under '" + plan.ns + "/'").c_str());
    std::fflush(stdout);
    Host host{std::move(plan), registry};
    std::printf("[prime] process '%s' ready\n", process.c_str());
    std::fflush(stdout);
    if (ready_fd >= 0) {
      [[maybe_unused]] const auto n = ::write(ready_fd, "ready\n", 6);
      ::close(ready_fd);
    }
    int signal = 0;
    sigwait(&stop_signals, &signal);
    host.stop();
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", process.empty() ? argv[0] : process.c_str(), e.what());
    return 1;
  }
}

}  // namespace prime::system
