:- module(robot_resources,
          [ read_robot_table/3,          % +Robot, -QTable, +Options
            read_robot_tables/4,         % +Robot, -QTable, -Visits, +Options
            write_robot_table/3,         % +Robot, +QTable, +Options
            read_robot_params/3,         % +Robot, -Params, +Options
            write_robot_params/3,        % +Robot, +Params, +Options
            hosted_robot/2,              % ?Robot, ?Props
            get_robot_table/3,           % deprecated: read_robot_table/3
            get_robot_tables/4,          % deprecated: read_robot_tables/4
            set_robot_table/3,           % deprecated: write_robot_table/3
            get_robot_params/3,          % deprecated: read_robot_params/3
            set_robot_params/3           % deprecated: write_robot_params/3
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
    robot was registered, e.g. `[algo(qlearning), shape([81,3])]`.
  - robot_resources:host_read_table(+Robot, -QTable, +Options) is det.
  - robot_resources:host_read_tables(+Robot, -QTable, -Visits, +Options) is det.
    The table and the visit counts, taken together (one snapshot).
  - robot_resources:host_write_table(+Robot, +QTable, +Options) is det.
  - robot_resources:host_read_params(+Robot, -Params, +Options) is det.
    Params is params(Layout, Samples, Values).
  - robot_resources:host_write_params(+Robot, +Params, +Options) is det.
    Params is params(Layout, Values).

The verbs are read and write, as everywhere on a Q-table's path (README,
"Words"). Deprecated, still served: the API's names of before,
get_robot_table/3, get_robot_tables/4, set_robot_table/3,
get_robot_params/3 and set_robot_params/3 (aliases of
read_robot_table/3 ... write_robot_params/3), and a host's hooks of before, table_get/3,
tables_get/4, table_set/3, params_get/3 and params_set/3 (called when
the host defines no clause of the new hook).

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
:- multifile robot_resources:robot/2, robot_resources:host_read_table/3,
             robot_resources:host_read_tables/4, robot_resources:host_write_table/3.
:- dynamic table/2.

robot_resources:robot(R, [shape(S)]) :- table(R, qtable(S, _)).
robot_resources:host_read_table(R, T, _) :- table(R, T).
robot_resources:host_read_tables(R, qtable(S, V), qtable(S, W), _) :-
    table(R, qtable(S, V)),
    maplist([_, 1.0]>>true, V, W).
robot_resources:host_write_table(R, T, _) :-
    retract(table(R, _)), assertz(table(R, T)).
```
*/

:- multifile
    robot/2,                    % ?Robot, ?Props
    host_read_table/3,          % +Robot, -QTable, +Options
    host_read_tables/4,         % +Robot, -QTable, -Visits, +Options
    host_write_table/3,         % +Robot, +QTable, +Options
    host_read_params/3,         % +Robot, -Params, +Options
    host_write_params/3,        % +Robot, +Params, +Options
    table_get/3,                % deprecated: host_read_table/3
    tables_get/4,               % deprecated: host_read_tables/4
    table_set/3,                % deprecated: host_write_table/3
    params_get/3,               % deprecated: host_read_params/3
    params_set/3,               % deprecated: host_write_params/3
    takes_packed_values/0.

%!  read_robot_table(+Robot, -QTable, +Options) is det.
%
%   QTable is the current Q-table of Robot, hosted by this process.
%   Options: timeout(Seconds).
%
%   @error existence_error(robot, Robot) if this process hosts no Robot.
%   @error existence_error(robot_resources_hook, host_read_table/3) if
%   the host defines no (succeeding) clause for it.
%   Errors of the host's hook pass through unchanged.

read_robot_table(Robot, QTable, Options) :-
    check_request(Robot, Options),
    hook(host_read_table(Robot, QTable, Options), table_get).

%!  read_robot_tables(+Robot, -QTable, -Visits, +Options) is det.
%
%   QTable and the visit counts Visits of Robot, taken in one snapshot.
%   Errors as read_robot_table/3.

read_robot_tables(Robot, QTable, Visits, Options) :-
    check_request(Robot, Options),
    hook(host_read_tables(Robot, QTable, Visits, Options), tables_get).

%!  write_robot_table(+Robot, +QTable, +Options) is det.
%
%   Replace the Q-table of Robot by QTable (the host validates it).
%   Errors as read_robot_table/3.
%
%   @error type_error(compound, QTable)

write_robot_table(Robot, QTable, Options) :-
    must_be(compound, QTable),
    check_request(Robot, Options),
    host_values(QTable, QTable1),
    hook(host_write_table(Robot, QTable1, Options), table_set).

%!  read_robot_params(+Robot, -Params, +Options) is det.
%
%   Params is params(Layout, Samples, Values), the current learnable
%   parameters of Robot, hosted by this process. Options: timeout(Seconds).
%   Errors as read_robot_table/3 (the hook host_read_params/3); a
%   robot that offers no parameters: the host's error (the bridge's is
%   existence_error(params, Robot)).

read_robot_params(Robot, Params, Options) :-
    check_request(Robot, Options),
    hook(host_read_params(Robot, Params, Options), params_get).

%!  write_robot_params(+Robot, +Params, +Options) is det.
%
%   Replace the parameters of Robot by Params = params(Layout, Values)
%   (the host validates them). Errors as read_robot_params/3.
%
%   @error type_error(compound, Params)

write_robot_params(Robot, Params, Options) :-
    must_be(compound, Params),
    check_request(Robot, Options),
    host_values(Params, Params1),
    hook(host_write_params(Robot, Params1, Options), params_set).

%!  get_robot_table(+Robot, -QTable, +Options) is det.
%!  get_robot_tables(+Robot, -QTable, -Visits, +Options) is det.
%!  set_robot_table(+Robot, +QTable, +Options) is det.
%!  get_robot_params(+Robot, -Params, +Options) is det.
%!  set_robot_params(+Robot, +Params, +Options) is det.
%
%   Deprecated names of read_robot_table/3, read_robot_tables/4,
%   write_robot_table/3, read_robot_params/3 and write_robot_params/3.

get_robot_table(Robot, QTable, Options) :- read_robot_table(Robot, QTable, Options).
get_robot_tables(Robot, QTable, Visits, Options) :-
    read_robot_tables(Robot, QTable, Visits, Options).
set_robot_table(Robot, QTable, Options) :- write_robot_table(Robot, QTable, Options).
get_robot_params(Robot, Params, Options) :- read_robot_params(Robot, Params, Options).
set_robot_params(Robot, Params, Options) :- write_robot_params(Robot, Params, Options).

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

%   hook(+Goal, +OldName): call the host's hook Goal; a host that defines
%   no clause of it but one of the hook's deprecated name OldName (same
%   arguments) has that called.
hook(Goal, OldName) :-
    functor(Goal, Name, Arity),
    (   \+ clause(Goal, _),
        Goal =.. [_|Args],
        Old =.. [OldName|Args],
        clause(Old, _)
    ->  Call = Old
    ;   Call = Goal
    ),
    (   call(Call)
    ->  true
    ;   existence_error(robot_resources_hook, Name/Arity)
    ).
