#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "prime/liberty.hpp"
#include "prime/radiant.hpp"
#include "prime/shm.hpp"
#include "prime/optimus.hpp"

namespace prime::test {

// Every medium the conformance suite runs on. A medium joins with one entry
// here (and, if it needs constructor arguments or carries sources its own way,
// a specialisation of Harness below).
using Media = ::testing::Types<liberty::Core, radiant::Core, shm::Core, optimus::Core>;

// How the suite makes a core, and a source it can publish into, on a medium.
// The default serves in-process media: an Event feeding core.source().
template <class M>
struct Harness {
  static std::unique_ptr<M> make_core() { return std::make_unique<M>(); }

  template <class T>
  struct Feed {
    std::unique_ptr<Event<T>> event;
    decltype(std::declval<M&>().source(std::declval<Event<T>&>())) source;

    void emit(T value) { event->emit(std::move(value)); }
    void emit(T value, Clock::time_point stamp) { event->emit(std::move(value), stamp); }
  };

  template <class T>
  static Feed<T> feed(M& core, std::string name, Qos qos = {}) {
    auto event = std::make_unique<Event<T>>();
    auto source = core.source(*event, std::move(name), qos);
    return {std::move(event), std::move(source)};
  }
};

// What a medium really carries, for the tests that depend on it. A harness
// that says nothing has the in-process answers; one that differs defines
//   static constexpr bool kPassesObjectsInPlace = false;      // values (and a block's exceptions) are
//                                                            // serialised: not copy-counted, not rethrown as their type
//   static constexpr bool kRunsLinkedBlocksInOneWorker = false;  // each linked block runs in a worker of its own
//   static constexpr bool kCarriesAnyType = false;           // sources carry only some types (Shm: trivially
//                                                            // copyable messages), so copy-counted objects stay out
//   static constexpr const char* kChainsAreAnotherMediums = "why";  // its core's chains are another medium's code
//                                                            // (tested there): the chain suite skips it, saying why
//   static constexpr const char* kChainKind = "service";     // what its chains' graph nodes are
template <class M>
constexpr bool passes_objects_in_place() {
  if constexpr (requires { Harness<M>::kPassesObjectsInPlace; }) return Harness<M>::kPassesObjectsInPlace;
  return true;
}
template <class M>
constexpr bool runs_linked_blocks_in_one_worker() {
  if constexpr (requires { Harness<M>::kRunsLinkedBlocksInOneWorker; }) return Harness<M>::kRunsLinkedBlocksInOneWorker;
  return true;
}
template <class M>
constexpr bool carries_any_type() {
  if constexpr (requires { Harness<M>::kCarriesAnyType; }) return Harness<M>::kCarriesAnyType;
  return true;
}
template <class M>
constexpr const char* chain_kind() {
  if constexpr (requires { Harness<M>::kChainKind; }) return Harness<M>::kChainKind;
  return "chain";
}
template <class M>
constexpr const char* chains_are_another_mediums() {
  if constexpr (requires { Harness<M>::kChainsAreAnotherMediums; }) return Harness<M>::kChainsAreAnotherMediums;
  return nullptr;
}

template <class M>
class MediumTest : public ::testing::Test {
 protected:
  using Core = M;
  template <class T>
  auto feed(std::string name, Qos qos = {}) {
    return Harness<M>::template feed<T>(*core, std::move(name), qos);
  }
  // A chain of `block`, carried by the medium (on Shm: a service).
  // (A harness may define `chain<In>(core, block, name)`; by default it is the core's.)
  template <class In = detail::Deduce, int&... ExplicitArgumentBarrier, class F>
  auto chain(F block, std::string name = "chain") {
    if constexpr (requires { Harness<M>::template chain<In>(*core, std::move(block), std::move(name)); })
      return Harness<M>::template chain<In>(*core, std::move(block), std::move(name));
    else
      return core->template chain<In>(std::move(block), std::move(name));
  }
  std::unique_ptr<M> core = Harness<M>::make_core();
};

class MediumName {
 public:
  template <class M>
  static std::string GetName(int) {
    return std::string{Harness<M>::make_core()->medium()};
  }
};

}  // namespace prime::test

#include "conformance/shm_harness.hpp"
#include "conformance/optimus_harness.hpp"
