#include "prime/system/system_file.hpp"

#include <dlfcn.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <set>

namespace prime::system {

namespace {

struct Reader {
  std::string file;

  [[noreturn]] void fail(int line, const std::string& what) const {
    throw Failure{{Errc::invalid_argument, file + ":" + std::to_string(line) + ": " + what}};
  }
  [[noreturn]] void fail(const YAML::Node& node, const std::string& what) const { fail(line(node), what); }
  static int line(const YAML::Node& node) { return node.Mark().line + 1; }

  // A map, each key once (YAML readers keep a repeated key; a system file
  // must not mean two things).
  void expect_map(const YAML::Node& node, const std::string& what) const {
    if (!node.IsMap()) fail(node, what + " must be a map");
    std::map<std::string, int> seen;
    for (const auto& entry : node)
      if (const auto [first, fresh] = seen.emplace(entry.first.Scalar(), line(entry.first)); !fresh)
        fail(entry.first, "'" + entry.first.Scalar() + "' appears twice in " + what + " (first at line " +
                              std::to_string(first->second) + ")");
  }
  std::string text(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) fail(node, what + " must be a text");
    return node.Scalar();
  }
  std::int64_t integer(const YAML::Node& node, const std::string& what) const {
    std::int64_t value{};
    if (!node.IsScalar() || !YAML::convert<std::int64_t>::decode(node, value)) fail(node, what + " must be an integer");
    return value;
  }
  std::vector<std::string> texts(const YAML::Node& node, const std::string& what) const {
    if (!node.IsSequence()) fail(node, what + " must be a list");
    std::vector<std::string> all;
    for (const auto& item : node) all.push_back(text(item, what + "'s entries"));
    return all;
  }
  // A parameter as YAML gives it: a quoted scalar is a string; otherwise
  // a bool, an integer or a number if it reads as one.
  ParamValue param(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) fail(node, what + " must be a bool, a number or a text");
    if (node.Tag() != "!") {
      std::int64_t i{};
      if (YAML::convert<std::int64_t>::decode(node, i)) return i;
      double d{};
      if (YAML::convert<double>::decode(node, d)) return d;
      bool b{};
      if (YAML::convert<bool>::decode(node, b)) return b;
    }
    return node.Scalar();
  }
  void known_keys(const YAML::Node& node, std::initializer_list<std::string_view> keys, const std::string& what) const {
    for (const auto& entry : node) {
      const auto key = entry.first.Scalar();
      if (std::find(keys.begin(), keys.end(), key) == keys.end()) {
        std::string known;
        for (auto k : keys) known += (known.empty() ? "" : ", ") + std::string{k};
        fail(entry.first, "unknown key '" + key + "' in " + what + " (it takes " + known + ")");
      }
    }
  }
};

// Values each reader of a topic may buffer, at most: a bound on what one
// line of a file makes every reader allocate.
constexpr std::int64_t kMaxCapacity = 1 << 20;

Qos topic_qos(const Reader& r, const std::string& name, const YAML::Node& node) {
  const auto what = "topic '" + name + "'";
  r.expect_map(node, what);
  r.known_keys(node, {"capacity", "overflow", "block_timeout_ms", "expose"}, what);
  Qos qos;
  if (node["capacity"]) {
    const auto capacity = r.integer(node["capacity"], what + ": capacity");
    if (capacity < 1 || capacity > kMaxCapacity)
      r.fail(node["capacity"], what + ": capacity must be from 1 to " + std::to_string(kMaxCapacity));
    qos.capacity = static_cast<std::size_t>(capacity);
  }
  if (node["overflow"]) {
    const auto overflow = r.text(node["overflow"], what + ": overflow");
    if (overflow == "drop_oldest") qos.overflow = Overflow::drop_oldest;
    else if (overflow == "block") qos.overflow = Overflow::block;
    else r.fail(node["overflow"], what + ": overflow is drop_oldest or block, not '" + overflow + "'");
  }
  if (node["block_timeout_ms"]) {
    const auto ms = r.integer(node["block_timeout_ms"], what + ": block_timeout_ms");
    if (ms < 0) r.fail(node["block_timeout_ms"], what + ": block_timeout_ms must not be negative");
    qos.block_timeout = std::chrono::milliseconds{ms};
  }
  return qos;
}

ProcessSpec process_spec(const Reader& r, const std::string& name, const YAML::Node& node) {
  const auto what = "process '" + name + "'";
  ProcessSpec process{.name = name, .line = Reader::line(node)};
  if (node.IsSequence()) {
    process.instances = r.texts(node, what);
    return process;
  }
  if (!node.IsMap()) r.fail(node, what + " must be a list of components or a map with 'components'");
  r.known_keys(node, {"components", "machine", "executable", "restart"}, what);
  if (!node["components"]) r.fail(node, what + " names no components");
  process.instances = r.texts(node["components"], what + ": components");
  if (node["machine"]) process.machine = r.text(node["machine"], what + ": machine");
  if (node["executable"]) process.executable = r.text(node["executable"], what + ": executable");
  if (node["restart"]) {
    const auto restart = r.text(node["restart"], what + ": restart");
    if (restart == "never") process.restart = Restart::never;
    else if (restart == "on_failure") process.restart = Restart::on_failure;
    else if (restart == "always") process.restart = Restart::always;
    else r.fail(node["restart"], what + ": restart is never, on_failure or always, not '" + restart + "'");
  }
  return process;
}

}  // namespace

const PlacementSpec* SystemSpec::placement(std::string_view name) const {
  for (const auto& p : placements)
    if (p.name == name) return &p;
  return nullptr;
}

SystemSpec load_system(const std::string& path, const std::vector<std::string>& overrides) {
  const Reader r{path};
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw Failure{{Errc::not_found, path + ": the system file cannot be read"}};
  } catch (const YAML::ParserException& e) {
    r.fail(e.mark.line + 1, "not YAML: " + e.msg);
  }
  if (!root.IsMap()) r.fail(root, "a system file is a map (system, components, topics, machines, placements)");
  r.known_keys(root, {"system", "executable", "namespace", "libraries", "machines", "components", "topics", "placements"},
               "the system file");
  SystemSpec system{.file = path};
  if (root["system"]) system.domain = r.text(root["system"], "system");
  if (root["executable"]) system.executable = r.text(root["executable"], "executable");
  if (root["namespace"]) system.ns = r.text(root["namespace"], "namespace");
  if (const auto libraries = root["libraries"]) {
    if (!libraries.IsSequence()) r.fail(libraries, "libraries must be a list");
    for (const auto& library : libraries) system.libraries.emplace_back(r.text(library, "a library"), Reader::line(library));
  }
  if (const auto machines = root["machines"]) {
    r.expect_map(machines, "machines");
    for (const auto& entry : machines) {
      const auto name = entry.first.Scalar();
      r.expect_map(entry.second, "machine '" + name + "'");
      r.known_keys(entry.second, {"redis"}, "machine '" + name + "'");
      if (entry.second["redis"]) system.redis[name] = r.text(entry.second["redis"], "machine '" + name + "': redis");
    }
  }
  const auto components = root["components"];
  if (!components) r.fail(root, "the system file has no components");
  r.expect_map(components, "components");
  for (const auto& entry : components) {
    const auto name = entry.first.Scalar();
    const auto what = "component '" + name + "'";
    r.expect_map(entry.second, what);
    r.known_keys(entry.second, {"type", "params"}, what);
    if (!entry.second["type"]) r.fail(entry.second, what + " has no type");
    Instance instance{name, r.text(entry.second["type"], what + ": type")};
    system.instance_lines[name] = Reader::line(entry.first);
    if (const auto params = entry.second["params"]) {
      r.expect_map(params, what + ": params");
      for (const auto& p : params) {
        const auto key = p.first.Scalar();
        instance.params[key] = r.param(p.second, what + ": parameter '" + key + "'");
        system.instance_lines[name + "." + key] = Reader::line(p.first);
      }
    }
    system.instances.push_back(std::move(instance));
  }
  if (const auto topics = root["topics"]) {
    r.expect_map(topics, "topics");
    for (const auto& entry : topics) {
      const auto name = entry.first.Scalar();
      system.topics[name] = topic_qos(r, name, entry.second);
      if (const auto expose = entry.second["expose"]) {
        bool on = false;
        if (!expose.IsScalar() || !YAML::convert<bool>::decode(expose, on)) r.fail(expose, "topic '" + name + "': expose must be true or false");
        if (on) system.exposed[name] = Reader::line(entry.first);
      }
    }
  }
  const auto placements = root["placements"];
  if (!placements) r.fail(root, "the system file has no placements");
  r.expect_map(placements, "placements");
  for (const auto& entry : placements) {
    PlacementSpec placement{.name = entry.first.Scalar(), .line = Reader::line(entry.first)};
    r.expect_map(entry.second, "placement '" + placement.name + "'");
    for (const auto& p : entry.second) placement.processes.push_back(process_spec(r, p.first.Scalar(), p.second));
    if (placement.processes.empty()) r.fail(entry.second, "placement '" + placement.name + "' has no processes");
    system.placements.push_back(std::move(placement));
  }
  for (const auto& o : overrides) {
    const auto equals = o.find('='), dot = o.find('.');
    if (equals == std::string::npos || dot == std::string::npos || dot > equals)
      throw Failure{{Errc::invalid_argument, "parameter override '" + o + "': write it as component.parameter=value"}};
    const auto name = o.substr(0, dot), key = o.substr(dot + 1, equals - dot - 1);
    auto instance = std::find_if(system.instances.begin(), system.instances.end(), [&](const auto& i) { return i.name == name; });
    if (instance == system.instances.end())
      throw Failure{{Errc::invalid_argument, "parameter override '" + o + "': " + path + " has no component '" + name + "'"}};
    YAML::Node value;
    try {
      value = YAML::Load(o.substr(equals + 1));
    } catch (const YAML::Exception&) {
      value = YAML::Node{o.substr(equals + 1)};
    }
    instance->params[key] = value.IsScalar() ? r.param(value, "override '" + o + "'") : ParamValue{o.substr(equals + 1)};
  }
  return system;
}

void load_libraries(const SystemSpec& system) {
  const auto dir = std::filesystem::path{system.file}.parent_path();
  for (const auto& [name, line] : system.libraries) {
    // A name with a slash is a path (beside the file when relative); one
    // without is looked up as dlopen does (LD_LIBRARY_PATH, the cache).
    const auto path = name.find('/') == std::string::npos ? name : std::filesystem::absolute(dir / name).lexically_normal().string();
    const auto before = Registry::global().problems().size();
    if (!::dlopen(path.c_str(), RTLD_NOW | RTLD_GLOBAL)) {
      const char* why = ::dlerror();
      throw Failure{{Errc::not_found, system.file + ":" + std::to_string(line) + ": the library of components '" + name +
                                          "' cannot be loaded: " + (why ? why : "dlopen failed")}};
    }
    if (const auto now = Registry::global().problems(); now.size() > before)
      throw Failure{{Errc::in_use, system.file + ":" + std::to_string(line) + ": the library of components '" + name +
                                       "': " + now[before]}};
  }
}

namespace {

// Who has which end of each topic and service, in one placement.
struct End {
  const Instance* instance;
  const Port* port;
  const ProcessSpec* process;
};
struct Ends {
  std::map<std::string, std::vector<End>> publishers, subscribers, servers, callers;
  std::map<std::string, const ProcessSpec*> process_of;  // instance → process
};

std::string list(const std::vector<std::string>& names) {
  std::string all;
  for (const auto& n : names) all += (all.empty() ? "" : ", ") + n;
  return all.empty() ? "none" : all;
}

Ends ends_of(const SystemSpec& system, const Registry& registry, const PlacementSpec& placement) {
  Ends ends;
  for (const auto& process : placement.processes)
    for (const auto& name : process.instances) ends.process_of.emplace(name, &process);
  for (const auto& instance : system.instances) {
    const auto* component = registry.find(instance.component);
    const auto where = ends.process_of.find(instance.name);
    if (!component || where == ends.process_of.end()) continue;
    for (const auto& port : component->ports()) {
      auto& side = port.kind == PortKind::publishes    ? ends.publishers
                   : port.kind == PortKind::subscribes ? ends.subscribers
                   : port.kind == PortKind::serves     ? ends.servers
                                                       : ends.callers;
      side[port.name].push_back({&instance, &port, where->second});
    }
  }
  return ends;
}

unsigned reach_between(const ProcessSpec& from, const ProcessSpec& to) {
  if (&from == &to) return Reach::here;
  return from.machine == to.machine ? Reach::same_machine : Reach::other_machine;
}

}  // namespace

std::vector<std::string> problems(const SystemSpec& system, const Registry& registry, std::string_view placement_name) {
  std::vector<std::string> found;
  const auto at = [&](int line, const std::string& what) { found.push_back(system.file + ":" + std::to_string(line) + ": " + what); };
  const auto line_of = [&](const std::string& key) {
    const auto l = system.instance_lines.find(key);
    return l == system.instance_lines.end() ? 0 : l->second;
  };
  const auto* placement = system.placement(placement_name);
  if (!placement) {
    std::vector<std::string> names;
    for (const auto& p : system.placements) names.push_back(p.name);
    found.push_back(system.file + ": no placement '" + std::string{placement_name} + "' (it has " + list(names) + ")");
    return found;
  }
  // Every program of the system knows every component of it (built in, or
  // from the file's libraries): where each link goes depends on all ends.
  for (const auto& instance : system.instances) {
    const auto* component = registry.find(instance.component);
    if (!component) {
      std::vector<std::string> known;
      for (const auto* c : registry.components()) known.push_back(c->type());
      at(line_of(instance.name), "component '" + instance.name + "': no component type '" + instance.component +
                                     "' is registered (known: " + list(known) +
                                     "); each program of a system knows every component of it, built in or from its libraries");
      continue;
    }
    if (auto problem = param_problem(*component, instance); !problem.empty()) {
      const auto key = problem.substr(problem.find("parameter '") + 11);
      at(line_of(instance.name + "." + key.substr(0, key.find('\''))), problem);
    }
  }
  // Each instance in exactly one process; each process's instances exist.
  std::map<std::string, const ProcessSpec*> placed;
  for (const auto& process : placement->processes) {
    for (const auto& name : process.instances) {
      const bool exists = std::any_of(system.instances.begin(), system.instances.end(), [&](const auto& i) { return i.name == name; });
      if (!exists) at(process.line, "placement '" + placement->name + "', process '" + process.name + "': no component '" + name + "'");
      else if (!placed.emplace(name, &process).second)
        at(process.line, "placement '" + placement->name + "': component '" + name + "' is placed in '" +
                             placed[name]->name + "' and in '" + process.name + "'");
    }
  }
  for (const auto& instance : system.instances)
    if (!placed.contains(instance.name))
      at(placement->line, "placement '" + placement->name + "' places component '" + instance.name + "' in no process");

  const auto ends = ends_of(system, registry, *placement);
  const auto needs_redis = [&](const End& a, const End& b) {
    if (a.process->machine == b.process->machine) return;
    for (const auto* p : {a.process, b.process})
      if (!system.redis.contains(p->machine))
        at(p->line, "process '" + p->name + "' on machine '" + p->machine + "' is linked to another machine ('" +
                        std::string{a.port->name} + "') and its machine has no Redis (machines: " + p->machine +
                        ": {redis: tcp://host:port})");
  };
  const auto crossing = [&](const End& a, const End& b) {
    if (a.process == b.process) return;
    if (!a.port->crosses_processes || !b.port->crosses_processes)
      at(line_of(b.instance->name), "'" + a.port->name + "' links '" + a.instance->name + "' and '" + b.instance->name +
                                        "' across processes, and its type " + a.port->message.describe() +
                                        " cannot cross them (not trivially copyable): place them in one process");
    needs_redis(a, b);
  };
  for (const auto& [topic, publishers] : ends.publishers)
    for (std::size_t i = 1; i < publishers.size(); ++i)
      at(line_of(publishers[i].instance->name), "topic '" + topic + "' has two publishers: '" + publishers[0].instance->name +
                                                    "' and '" + publishers[i].instance->name + "'");
  for (const auto& [topic, subscribers] : ends.subscribers) {
    const auto publisher = ends.publishers.find(topic);
    if (publisher == ends.publishers.end()) continue;  // from outside the system, through Shm
    const auto& p = publisher->second.front();
    for (const auto& s : subscribers) {
      if (!(s.port->message == p.port->message))
        at(line_of(s.instance->name), "'" + s.instance->name + "' subscribes to '" + topic + "' as " + s.port->message.describe() +
                                          ", and '" + p.instance->name + "' publishes it as " + p.port->message.describe());
      else crossing(p, s);
    }
  }
  // An exposed topic goes into the Shm domain: its type must cross processes.
  for (const auto& [topic, line] : system.exposed)
    if (const auto publishers = ends.publishers.find(topic); publishers != ends.publishers.end())
      if (const auto& p = publishers->second.front(); !p.port->crosses_processes)
        at(line, "topic '" + topic + "' is exposed, and its type " + p.port->message.describe() +
                     " cannot leave its process (not trivially copyable)");
  for (const auto& [service, servers] : ends.servers)
    for (std::size_t i = 1; i < servers.size(); ++i)
      at(line_of(servers[i].instance->name), "service '" + service + "' is served twice: by '" + servers[0].instance->name +
                                                 "' and by '" + servers[i].instance->name + "'");
  for (const auto& [service, callers] : ends.callers) {
    const auto server = ends.servers.find(service);
    for (const auto& c : callers) {
      if (server == ends.servers.end()) {
        at(line_of(c.instance->name), "'" + c.instance->name + "' calls the service '" + service + "', which nobody serves");
        continue;
      }
      const auto& s = server->second.front();
      if (!(c.port->message == s.port->message) || !(*c.port->reply == *s.port->reply))
        at(line_of(c.instance->name), "'" + c.instance->name + "' calls '" + service + "' with " + c.port->message.describe() +
                                          " for " + c.port->reply->describe() + ", and '" + s.instance->name + "' serves " +
                                          s.port->message.describe() + " for " + s.port->reply->describe());
      else crossing(s, c);
    }
  }
  return found;
}

std::vector<std::string> start_order(const SystemSpec& system, const Registry& registry, std::string_view placement_name) {
  const auto* placement = system.placement(placement_name);
  if (!placement) return {};
  const auto ends = ends_of(system, registry, *placement);
  // Process → the processes serving what it calls.
  std::map<std::string, std::set<std::string>> after;
  for (const auto& [service, callers] : ends.callers)
    if (const auto servers = ends.servers.find(service); servers != ends.servers.end())
      for (const auto& c : callers)
        for (const auto& s : servers->second)
          if (c.process != s.process) after[c.process->name].insert(s.process->name);
  std::vector<std::string> order;
  std::set<std::string> started;
  while (started.size() < placement->processes.size()) {
    bool progressed = false;
    for (const auto& p : placement->processes) {
      if (started.contains(p.name)) continue;
      const auto& needs = after[p.name];
      if (std::all_of(needs.begin(), needs.end(), [&](const auto& n) { return started.contains(n); })) {
        order.push_back(p.name);
        started.insert(p.name);
        progressed = true;
      }
    }
    if (!progressed)  // calls in a cycle: the rest as listed
      for (const auto& p : placement->processes)
        if (started.insert(p.name).second) order.push_back(p.name);
  }
  return order;
}

Plan plan_of(const SystemSpec& system, const Registry& registry, std::string_view placement_name, std::string_view process_name) {
  if (auto found = problems(system, registry, placement_name); !found.empty())
    throw Failure{{Errc::invalid_argument, found.front()}};
  const auto* placement = system.placement(placement_name);
  const auto me = std::find_if(placement->processes.begin(), placement->processes.end(),
                               [&](const auto& p) { return p.name == process_name; });
  if (me == placement->processes.end())
    throw Failure{{Errc::invalid_argument, system.file + ": placement '" + placement->name + "' has no process '" +
                                               std::string{process_name} + "'"}};
  Plan plan{.process = me->name, .topic_qos = system.topics, .ns = system.ns, .shm_domain = system.domain,
            .join_domain = true, .optimus_domain = system.domain};
  if (const auto redis = system.redis.find(me->machine); redis != system.redis.end()) plan.redis = redis->second;
  for (const auto& name : me->instances)
    for (const auto& instance : system.instances)
      if (instance.name == name) plan.instances.push_back(instance);
  const auto ends = ends_of(system, registry, *placement);
  // A topic's QoS is the system file's, else its publisher's: every end
  // opens it alike.
  for (const auto& [topic, publishers] : ends.publishers) plan.topic_qos.emplace(topic, publishers.front().port->qos);
  const auto mine = [&](const End& e) { return e.process == &*me; };
  const auto add = [&](const std::string& name, unsigned reach) { plan.reach[name] |= reach; };
  // Outputs and services reach every other end; inputs and calls come from one.
  // A topic nobody in the system reads (or one the file exposes) goes into
  // the Shm domain too: for tools and programs outside the system.
  for (const auto& [topic, publishers] : ends.publishers) {
    const auto subscribers = ends.subscribers.find(topic);
    for (const auto& p : publishers) {
      if (!mine(p)) continue;
      if ((subscribers == ends.subscribers.end() || system.exposed.contains(topic)) && p.port->crosses_processes)
        add(topic, Reach::same_machine);
      if (subscribers != ends.subscribers.end())
        for (const auto& s : subscribers->second) add(topic, reach_between(*me, *s.process));
    }
  }
  for (const auto& [topic, subscribers] : ends.subscribers) {
    const auto publishers = ends.publishers.find(topic);
    for (const auto& s : subscribers) {
      if (!mine(s)) continue;
      if (publishers != ends.publishers.end()) add(topic, reach_between(*me, *publishers->second.front().process));
      else if (s.port->crosses_processes) add(topic, Reach::same_machine);  // from outside the system, through Shm
    }
  }
  for (const auto& [service, servers] : ends.servers) {
    const auto callers = ends.callers.find(service);
    for (const auto& s : servers) {
      if (!mine(s)) continue;
      add(service, Reach::here);
      if (callers != ends.callers.end())
        for (const auto& c : callers->second) add(service, reach_between(*me, *c.process));
    }
  }
  for (const auto& [service, callers] : ends.callers) {
    const auto servers = ends.servers.find(service);
    for (const auto& c : callers)
      if (mine(c) && servers != ends.servers.end()) add(service, reach_between(*me, *servers->second.front().process));
  }
  return plan;
}

}  // namespace prime::system
