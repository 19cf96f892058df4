:- module(robot_resources,
          [ get_robot_table/3,          % +Robot, -QTable, +Options
            get_robot_tables/4,         % +Robot, -QTable, -Visits, +Options
            set_robot_table/3,          % +Robot, +QTable, +Options
            get_robot_params/3,         % +Robot, -Params, +Options
            set_robot_params/3,         % +Robot, +Params, +Options
            hosted_robot/2              % ?Robot, ?Props
          ]).
:- autoload(library(error), [must_be/2, existence_error/2]).
:- use_module(float_vectors, [packed_vector/1, vector_floats/2]).

/** <module> The resources a host process offers to agents: robots' tables and parameters

The platform knows nothing about robots. A process that hosts robots (a
robot process: the Python bridge, pybridge/robot_bridge.pl) says which
robots it hosts and how their tables are read and written by defining
clauses of the multifile hooks below; agents (e.g. the dFRL agent,
dfrl_agent/dfrl_agent.pl) use only the exported predicates of this module.

Hooks, defined as clauses in this module:

  - robot_resources:robot(?Robot, ?Props) is nondet.
    The robots this process hosts, with the properties given when the
    robot was registered, e.g. `[algorithm(qlearning), shape([81,3])]`.
  - robot_resources:table_get(+Robot, -QTable, +Options) is det.
  - robot_resources:tables_get(+Robot, -QTable, -Visits, +Options) is det.
    The table and the visit counts, taken together (one snapshot).
  - robot_resources:table_set(+Robot, +QTable, +Options) is det.
  - robot_resources:params_get(+Robot, -Params, +Options) is det.
    Params is params(Layout, Samples, Values).
  - robot_resources:params_set(+Robot, +Params, +Options) is det.
    Params is params(Layout, Values).

A table is qtable(Shape, Values): Shape = [NStates, NActions], Values the
flat row-major list of NStates*NActions floats (visit counts as floats
too). A robot's learnable parameters (a function learner's, or a tabular
one's that also offers them) are one flat list of floats Values with a
Layout, a list Name-Dims of blocks (each row-major, in order), and
Samples, the number of steps the learner has learnt from (the FedAvg
weight). The props of a robot say what it offers: shape(Shape) for a
table, layout(Layout) for parameters, learner(tabular|function).
Options: timeout(Seconds), how long the host may take to answer; other
options of a write say where it comes from (round(N), agent(A), ...).

Values may also be *packed* (fts(String), see float_vectors.pl): the
form the dFRL agent carries tables in. A read with the option
values(packed) may give them packed (a host that does not, gives a
list: the agent's maths takes both). A write hands packed values to the
host only if it says it takes them, with the clause
`robot_resources:takes_packed_values.` (the Python bridge does); for
any other host they are made a list first.

A host with its tables in Prolog memory (as the platform's tests have):

```
:- multifile robot_resources:robot/2, robot_resources:table_get/3,
             robot_resources:tables_get/4, robot_resources:table_set/3.
:- dynamic table/2.

robot_resources:robot(R, [shape(S)]) :- table(R, qtable(S, _)).
robot_resources:table_get(R, T, _) :- table(R, T).
robot_resources:tables_get(R, qtable(S, V), qtable(S, W), _) :-
    table(R, qtable(S, V)),
    maplist([_, 1.0]>>true, V, W).
robot_resources:table_set(R, T, _) :-
    retract(table(R, _)), assertz(table(R, T)).
```
*/

:- multifile
    robot/2,                    % ?Robot, ?Props
    table_get/3,                % +Robot, -QTable, +Options
    tables_get/4,               % +Robot, -QTable, -Visits, +Options
    table_set/3,                % +Robot, +QTable, +Options
    params_get/3,               % +Robot, -Params, +Options
    params_set/3,               % +Robot, +Params, +Options
    takes_packed_values/0.

%!  get_robot_table(+Robot, -QTable, +Options) is det.
%
%   QTable is the current Q-table of Robot, hosted by this process.
%   Options: timeout(Seconds).
%
%   @error existence_error(robot, Robot) if this process hosts no Robot.
%   @error existence_error(robot_resources_hook, table_get/3) if the
%   host defines no (succeeding) clause for it.
%   Errors of the host's hook pass through unchanged.

get_robot_table(Robot, QTable, Options) :-
    check_request(Robot, Options),
    hook(table_get(Robot, QTable, Options)).

%!  get_robot_tables(+Robot, -QTable, -Visits, +Options) is det.
%
%   QTable and the visit counts Visits of Robot, taken in one snapshot.
%   Errors as get_robot_table/3.

get_robot_tables(Robot, QTable, Visits, Options) :-
    check_request(Robot, Options),
    hook(tables_get(Robot, QTable, Visits, Options)).

%!  set_robot_table(+Robot, +QTable, +Options) is det.
%
%   Replace the Q-table of Robot by QTable (the host validates it).
%   Errors as get_robot_table/3.
%
%   @error type_error(compound, QTable)

set_robot_table(Robot, QTable, Options) :-
    must_be(compound, QTable),
    check_request(Robot, Options),
    host_values(QTable, QTable1),
    hook(table_set(Robot, QTable1, Options)).

%!  get_robot_params(+Robot, -Params, +Options) is det.
%
%   Params is params(Layout, Samples, Values), the current learnable
%   parameters of Robot, hosted by this process. Options: timeout(Seconds).
%   Errors as get_robot_table/3 (the hook params_get/3); a robot that
%   offers no parameters: the host's error (the bridge's is
%   existence_error(params, Robot)).

get_robot_params(Robot, Params, Options) :-
    check_request(Robot, Options),
    hook(params_get(Robot, Params, Options)).

%!  set_robot_params(+Robot, +Params, +Options) is det.
%
%   Replace the parameters of Robot by Params = params(Layout, Values)
%   (the host validates them). Errors as get_robot_params/3.
%
%   @error type_error(compound, Params)

set_robot_params(Robot, Params, Options) :-
    must_be(compound, Params),
    check_request(Robot, Options),
    host_values(Params, Params1),
    hook(params_set(Robot, Params1, Options)).

%!  hosted_robot(?Robot, ?Props) is nondet.
%
%   Robot is hosted by this process, registered with Props.

hosted_robot(Robot, Props) :-
    robot(Robot, Props).

%   The values of a write as the host takes them: packed ones become a
%   list unless it takes packed values.
host_values(Item0, Item) :-
    (   Item0 =.. [F, A, V0],
        packed_vector(V0),
        \+ takes_packed_values
    ->  vector_floats(V0, V),
        Item =.. [F, A, V]
    ;   Item = Item0
    ).

check_request(Robot, Options) :-
    must_be(atomic, Robot),
    must_be(list, Options),
    (   robot(Robot, _)
    ->  true
    ;   existence_error(robot, Robot)
    ).

hook(Goal) :-
    (   call(Goal)
    ->  true
    ;   functor(Goal, Name, Arity),
        existence_error(robot_resources_hook, Name/Arity)
    ).
