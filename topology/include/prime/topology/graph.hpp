#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <iterator>
#include <memory>
#include <sstream>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

namespace prime {

// What a topology is made of, for people: every chain, source and combinator
// carries the graph of what it was built from, and prints it as text or as
// Graphviz DOT. Built while linking, never touched on the data path.
//
// Graphs share their parts, so linking costs the same however large the two
// sides are; the list of nodes and edges is worked out only when asked for.
// Immutable, so thread-safe.
class Graph {
 public:
  struct Node {
    std::uint64_t id;
    std::string name;
    std::string kind;    // "chain", "source", "collector", "sync", ...
    std::string medium;  // "liberty", "radiant", ...
    friend bool operator==(const Node&, const Node&) = default;
  };
  struct Edge {
    std::uint64_t from;
    std::uint64_t to;
    friend bool operator==(const Edge&, const Edge&) = default;
  };

  Graph() = default;  // empty: no node, joins to nothing

  // One node that is both where data enters and where it leaves.
  static Graph node(std::string name, std::string kind, std::string medium) {
    static std::atomic<std::uint64_t> next_id{1};
    Node n{next_id.fetch_add(1, std::memory_order_relaxed), std::move(name), std::move(kind), std::move(medium)};
    return make(Part::Kind::node, {}, {n}, {n});
  }

  // `first` feeds `second`: every exit of one is joined to every entry of the other.
  static Graph sequence(const Graph& first, const Graph& second) {
    if (!first.root_) return second;
    if (!second.root_) return first;
    return make(Part::Kind::sequence, {first.root_, second.root_}, first.entries(), second.exits());
  }

  // Side by side: data may enter or leave through any of the parts.
  static Graph parallel(std::initializer_list<const Graph*> parts) {
    std::vector<std::shared_ptr<const Part>> joined;
    std::vector<Node> entries, exits;
    for (const Graph* part : parts) {
      if (!part->root_) continue;
      joined.push_back(part->root_);
      append_unique(entries, part->entries());
      append_unique(exits, part->exits());
    }
    return make(Part::Kind::parallel, std::move(joined), std::move(entries), std::move(exits));
  }

  // An edge back from this graph's exits to `target`'s entries (a loop).
  [[nodiscard]] Graph looping_back_to(const Graph& target) const {
    if (!root_ || !target.root_) return *this;
    return make(Part::Kind::loop, {root_, target.root_}, entries(), exits());
  }

  [[nodiscard]] const std::vector<Node>& entries() const noexcept { return root_ ? root_->entries : none(); }
  [[nodiscard]] const std::vector<Node>& exits() const noexcept { return root_ ? root_->exits : none(); }
  [[nodiscard]] std::vector<Node> nodes() const { return flatten().nodes; }
  [[nodiscard]] std::vector<Edge> edges() const { return flatten().edges; }

  // "lidar [source, liberty] -> localize [chain, radiant]", one edge a line,
  // then any node that has no edge. Names that repeat get a "#id" suffix.
  [[nodiscard]] std::string text() const {
    const Flat flat = flatten();
    const auto label = labeller(flat);
    std::ostringstream out;
    std::unordered_set<std::uint64_t> linked;
    for (const auto& e : flat.edges) {
      out << label(e.from) << " -> " << label(e.to) << '\n';
      linked.insert(e.from);
      linked.insert(e.to);
    }
    for (const auto& n : flat.nodes)
      if (!linked.contains(n.id)) out << label(n.id) << '\n';
    return out.str();
  }

  [[nodiscard]] std::string dot() const {
    const Flat flat = flatten();
    std::ostringstream out;
    out << "digraph prime {\n  rankdir=LR;\n";
    for (const auto& n : flat.nodes) {
      out << "  n" << n.id << " [label=\"" << escaped(n.name) << "\\n" << escaped(n.kind) << ", "
          << escaped(n.medium) << "\", shape=" << shape(n.kind) << "];\n";
    }
    for (const auto& e : flat.edges) out << "  n" << e.from << " -> n" << e.to << ";\n";
    out << "}\n";
    return out.str();
  }

 private:
  struct Part {
    enum class Kind { node, sequence, parallel, loop };
    Kind kind;
    std::vector<std::shared_ptr<const Part>> parts;  // sequence: {first, second}; loop: {body, target}
    std::vector<Node> entries;
    std::vector<Node> exits;

    Part(Kind k, std::vector<std::shared_ptr<const Part>> p, std::vector<Node> in, std::vector<Node> out)
        : kind{k}, parts{std::move(p)}, entries{std::move(in)}, exits{std::move(out)} {}
    Part(const Part&) = delete;
    Part& operator=(const Part&) = delete;

    // Releases a long chain of parts without recursing once per part: a part
    // this one owns alone hands its own parts over before it goes.
    ~Part() {
      auto pending = std::move(parts);
      while (!pending.empty()) {
        auto part = std::move(pending.back());
        pending.pop_back();
        if (part.use_count() == 1) {  // the last owner: no other thread can reach it
          auto& children = const_cast<Part&>(*part).parts;  // made non-const by make()
          std::move(children.begin(), children.end(), std::back_inserter(pending));
          children.clear();
        }
      }
    }
  };
  struct Flat {
    std::vector<Node> nodes;
    std::vector<Edge> edges;
  };
  struct EdgeHash {
    std::size_t operator()(const Edge& e) const noexcept {
      return std::hash<std::uint64_t>{}(e.from * 0x9E3779B97F4A7C15ull ^ e.to);
    }
  };

  explicit Graph(std::shared_ptr<const Part> root) : root_{std::move(root)} {}
  static Graph make(Part::Kind kind, std::vector<std::shared_ptr<const Part>> parts, std::vector<Node> entries,
                    std::vector<Node> exits) {
    return Graph{std::make_shared<Part>(kind, std::move(parts), std::move(entries), std::move(exits))};
  }

  static const std::vector<Node>& none() {
    static const std::vector<Node> empty;
    return empty;
  }
  static void append_unique(std::vector<Node>& to, const std::vector<Node>& from) {
    for (const auto& n : from)
      if (std::find(to.begin(), to.end(), n) == to.end()) to.push_back(n);
  }

  // Every node and edge once, parts before what joins them, walked without
  // recursion: a chain linked at run time may be very long.
  [[nodiscard]] Flat flatten() const {
    Flat flat;
    if (!root_) return flat;
    std::unordered_set<std::uint64_t> nodes;
    std::unordered_set<Edge, EdgeHash> edges;
    std::unordered_set<const Part*> done;
    const auto join = [&](const std::vector<Node>& from, const std::vector<Node>& to) {
      for (const auto& f : from)
        for (const auto& t : to)
          if (edges.insert({f.id, t.id}).second) flat.edges.push_back({f.id, t.id});
    };
    struct Frame {
      const Part* part;
      std::size_t next_child;
    };
    std::vector<Frame> stack{{root_.get(), 0}};
    while (!stack.empty()) {
      Frame& top = stack.back();
      if (top.next_child < top.part->parts.size()) {
        const Part* child = top.part->parts[top.next_child++].get();
        if (!done.contains(child)) stack.push_back({child, 0});
        continue;
      }
      const Part& part = *top.part;
      stack.pop_back();
      if (!done.insert(&part).second) continue;
      switch (part.kind) {
        case Part::Kind::node:
          if (nodes.insert(part.entries.front().id).second) flat.nodes.push_back(part.entries.front());
          break;
        case Part::Kind::sequence:
        case Part::Kind::loop: join(part.parts[0]->exits, part.parts[1]->entries); break;
        case Part::Kind::parallel: break;
      }
    }
    return flat;
  }

  static std::function<std::string(std::uint64_t)> labeller(const Flat& flat) {
    std::unordered_map<std::string, int> uses;
    std::unordered_map<std::uint64_t, const Node*> by_id;
    for (const auto& n : flat.nodes) {
      ++uses[n.name];
      by_id[n.id] = &n;
    }
    return [uses = std::move(uses), by_id = std::move(by_id)](std::uint64_t id) {
      const Node& n = *by_id.at(id);
      std::string label = n.name;
      if (uses.at(n.name) > 1) label.append("#").append(std::to_string(n.id));
      return label.append(" [").append(n.kind).append(", ").append(n.medium).append("]");
    };
  }

  static std::string escaped(const std::string& s) {
    std::string r;
    for (char c : s) {
      if (c == '"' || c == '\\') r += '\\';
      r += c;
    }
    return r;
  }
  static const char* shape(const std::string& kind) {
    if (kind == "source") return "ellipse";
    if (kind == "sync" || kind == "collector" || kind == "fork") return "diamond";
    return "box";
  }

  std::shared_ptr<const Part> root_;
};

}  // namespace prime
