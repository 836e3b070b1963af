#pragma once

#include <string>
#include <utility>
#include <vector>

#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"

namespace prime {

namespace detail {

template <class Body>
struct Each {
  Body body;

  std::vector<typename Body::output_type> operator()(std::vector<typename Body::input_type> in) const {
    std::vector<typename Body::output_type> out;
    out.reserve(in.size());
    for (auto& item : in) out.push_back(body(std::move(item)));
    return out;
  }
};

}  // namespace detail

// Chain<vector<In>, vector<Out>>: the body applied to every element, in order.
template <Medium M, Chain Body>
[[nodiscard]] auto foreach(M& core, Body body, std::string name = "foreach") {
  Graph graph = Graph::sequence(Graph::node(std::move(name), "foreach", std::string{core.medium()}), body.graph());
  return core.template chain<std::vector<typename Body::input_type>>(detail::Each<Body>{std::move(body)},
                                                                     std::move(graph));
}

}  // namespace prime
