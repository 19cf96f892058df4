:- module(bounds_limits,
          [ node_limits/2,              % +Node, -Limits
            limit/3,                    % +Limits, +Name, -Limit
            over/2,                     % +Value, +Limit
            module_size/2,              % +Module, -Bytes
            check_module_size/2,        % +Node, +Bytes
            thread_stacks/2             % +Thread, -Bytes
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(aggregate), [aggregate_all/3]).
:- use_module(node, [node_option/3]).

/** <module> The limits of an agent's call and what they are compared with

The per-call limits of agent_bounds.pl are the record limits(CPU, Stack,
Module, Posts, Log, Wall, Idle), read from a node's options once per
call (node_limits/2), one field at a time by limit/3; every limit may be
`infinite`. The measures that are compared with them and cost more than
a statistics key: the bytes of an agent's module, the stacks of a
thread.
*/

%!  node_limits(+Node, -Limits) is det.
%!  limit(+Limits, +Name, -Limit) is det.
%!  over(+Value, +Limit) is semidet.
%
%   The per-call limits of Node's agents, one of them (Name `cpu`,
%   `stack`, `module`, `posts`, `log`, `wall` or `idle`), and whether
%   Value is over Limit (never over `infinite`).

node_limits(Node, limits(CPU, Stack, Module, Posts, Log, Wall, Idle)) :-
    node_option(Node, agent_cpu_limit, CPU),
    node_option(Node, agent_stack_limit, Stack),
    node_option(Node, agent_module_limit, Module),
    node_option(Node, agent_post_limit, Posts),
    node_option(Node, agent_log_limit, Log),
    node_option(Node, agent_wall_limit, Wall),
    node_option(Node, agent_idle_limit, Idle).

limit(limits(L, _, _, _, _, _, _), cpu, L).
limit(limits(_, L, _, _, _, _, _), stack, L).
limit(limits(_, _, L, _, _, _, _), module, L).
limit(limits(_, _, _, L, _, _, _), posts, L).
limit(limits(_, _, _, _, L, _, _), log, L).
limit(limits(_, _, _, _, _, L, _), wall, L).
limit(limits(_, _, _, _, _, _, L), idle, L).

over(Value, Limit) :-
    Limit \== infinite,
    Value > Limit.

%!  module_size(+Module, -Bytes) is det.
%
%   Bytes held by the clauses of Module's own predicates.

module_size(Module, Size) :-
    aggregate_all(sum(B),
                  ( current_predicate(_, Module:H),
                    \+ predicate_property(Module:H, imported_from(_)),
                    predicate_property(Module:H, size(B))
                  ),
                  Size).

%!  check_module_size(+Node, +Bytes) is det.
%
%   An arriving agent's module, of Bytes, against Node's
%   agent_module_limit.
%
%   @error resource_error(agent_memory) if it is over.

check_module_size(Node, Size) :-
    node_option(Node, agent_module_limit, Max),
    (   over(Size, Max)
    ->  throw(error(resource_error(agent_memory),
                    context(_, too_large(Size, Max))))
    ;   true
    ).

%!  thread_stacks(+Thread, -Bytes) is det.
%
%   The stacks a thread has allocated. In SWI-Prolog 9.0.4 the key
%   `stack` of thread_statistics/3 gives the stacks of the whole process,
%   the same for every thread (a memory bomb's stacks were charged to
%   every call running beside it, and the budget stopped an innocent
%   one); global, local and trail are the thread's own.

thread_stacks(Thread, Bytes) :-
    thread_statistics(Thread, global, G),
    thread_statistics(Thread, local, L),
    thread_statistics(Thread, trail, T),
    Bytes is G + L + T.
