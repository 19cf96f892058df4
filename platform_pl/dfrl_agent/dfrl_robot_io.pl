:- module(dfrl_robot_io,
          [ read_robot/5,               % +Carried, +Method, +Robot, +Options, -Item
            write_robot/3,              % +Table, +Robot, +Options
            item_bytes/2                % +Item, -Bytes
          ]).
:- use_module('../robot_resources',
              [ read_robot_table/3, read_robot_tables/4, write_robot_table/3,
                read_robot_params/3, write_robot_params/3 ]).
:- use_module('../agent_bounds', [bounds_park/1]).
:- use_module('../tartarus', [current_node/1]).
:- use_module(dfrl_lease, [lease_fenced/4, lease_note_write/3]).
:- use_module('../float_vectors',
              [vector_length/2, packed_vector/1, float_vectors_native/1]).
:- autoload(library(lists), [sum_list/2]).

/** <module> Reading and writing a robot for the dFRL agent

What the agent (dfrl_agent.pl) and its clones (dfrl_tree.pl) read from
the robot of the stop they are at, and write into it: through the
resource hook of the host process (robot_resources.pl).

A robot may make the agent wait (a synchronous robot answers at its
next respite boundary), so each hook call is parked
(agent_bounds:bounds_park/1): it holds no run slot of the node, and its
time counts against agent_idle_limit, not agent_wall_limit.
*/

%!  read_robot(+Carried, +Method, +Robot, +Options, -Item) is det.
%
%   Item is what Robot gives to the aggregate: params(Layout, Samples,
%   Values) when Carried is `params`; else qtable_visits(Shape, Values,
%   Visits) when Method uses visit counts, qtable(Shape, Values) when it
%   does not. Options are those of the resource hook (timeout, round,
%   agent, epoch); the values are asked for packed (float_vectors.pl)
%   where its C library is built. Raises what the hook raises.

read_robot(params, _, Robot, Options0, Params) :-
    !,
    read_options(Options0, Options),
    bounds_park(read_robot_params(Robot, Params, Options)).
read_robot(tables, Method, Robot, Options0, Table) :-
    read_options(Options0, Options),
    (   dfrl_aggregation:method_uses_visits(Method)
    ->  bounds_park(read_robot_tables(Robot, qtable(S, V), qtable(S, W), Options)),
        Table = qtable_visits(S, V, W)
    ;   bounds_park(read_robot_table(Robot, Table, Options))
    ).

%   Values are asked for packed where packed maths runs in C: without the
%   library, lists are faster (float_vectors.pl).
read_options(Options, [values(packed)|Options]) :-
    float_vectors_native(true),
    !.
read_options(Options, Options).

%!  write_robot(+Table, +Robot, +Options) is det.
%
%   Write the round's aggregate Table (qtable(Shape, Values) or
%   params(Layout, Values)) into Robot, unless the robot's node fences
%   the write (dfrl_lease:lease_fenced/4): it has seen a higher epoch of
%   the agent of Options, or this robot was written in this round (or a
%   later one) already.
%
%   @error permission_error(write, robot_table, Robot) with the reason
%   as context, for a fenced write (nothing written).

write_robot(Table, Robot, Options) :-
    current_node(Node),
    Fence = [robot(Robot)|Options],
    lease_fenced(Node, Fence, Verdict, Why),
    (   Verdict == ok
    ->  write_robot_(Table, Robot, Options),
        lease_note_write(Node, Robot, Options)
    ;   throw(error(permission_error(write, robot_table, Robot),
                    context(dfrl_robot_io:write_robot/3, Why)))
    ).

write_robot_(params(L, V), Robot, Options) :-
    !,
    bounds_park(write_robot_params(Robot, params(L, V), Options)).
write_robot_(Table, Robot, Options) :-
    bounds_park(write_robot_table(Robot, Table, Options)).

%!  item_bytes(+Item, -Bytes) is det.
%
%   Bytes estimates the payload size of Item (a robot's item or a
%   finished table): 10 per float, as the fast serialisation on the wire
%   (and the packed form, float_vectors.pl).

item_bytes(Item, Bytes) :-
    (   compound(Item)
    ->  findall(N, ( arg(_, Item, L), vector(L), vector_length(L, N) ), Ns),
        sum_list(Ns, Total),
        Bytes is 10 * Total
    ;   Bytes = 0
    ).

vector(L) :-
    (   is_list(L)
    ->  true
    ;   packed_vector(L)
    ).
