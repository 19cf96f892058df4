:- module(bridge_tables,
          [ read_table/2,               % +Robot, -Table
            read_table/3,               % +Robot, -Table, +Options
            write_table/2,              % +Robot, +Table
            write_table/3,              % +Robot, +Table, +Options
            read_visits/2,              % +Robot, -Table
            read_visits/3,              % +Robot, -Table, +Options
            read_table_and_visits/3,    % +Robot, -Table, -Visits
            read_table_and_visits/4,    % +Robot, -Table, -Visits, +Options
            read_params/2,              % +Robot, -Params
            read_params/3,              % +Robot, -Params, +Options
            write_params/2,             % +Robot, +Params
            write_params/3              % +Robot, +Params, +Options
          ]).
:- use_module(bridge_queue, [bridge_call/5]).
:- use_module(bridge_registry,
              [ registered/1, offers/2, check_shape/1, layout_size/2, bridge_codec/1 ]).
:- use_module(table_codec,
              [ encode_values/3, decode_values/2, fts_encoded/2, float_list/2 ]).
:- use_module('../platform_pl/platform_errors', [abbreviated/2]).
:- use_module('../platform_pl/float_vectors',
              [ packed_vector/1, vector_length/2, vector_floats/2 ]).
:- autoload(library(error),
            [ must_be/2, domain_error/2, type_error/2, instantiation_error/1 ]).
:- autoload(library(lists), [append/3]).
:- autoload(library(apply), [include/3]).

/** <module> The bridge's table and parameter API

What an agent thread calls to read or write a robot of this process
(robot_bridge.pl has the whole story): read_table/3 and write_table/3
for a Q-table, read_visits/3 and read_table_and_visits/4 for visit
counts, read_params/3 and write_params/3 for a parameter vector. Each
checks the request against the registry (bridge_registry.pl), posts it
through the request queue (bridge_queue.pl) and decodes the reply;
tables and parameters share one checked write path (write_checked/5).
*/

%!  read_table(+Robot, -Table) is det.
%!  read_table(+Robot, -Table, +Options) is det.
%
%   Table is qtable(Shape, Values), a snapshot of Robot's Q-table taken by
%   the host between two learning steps. Options: timeout(Seconds),
%   values(packed) (fts data are left packed, float_vectors.pl).
%
%   @error existence_error(robot, Robot) if Robot is not registered here.
%   @error existence_error(qtable, Robot) if Robot offers no Q-table.
%   @error timeout_error(bridge, Robot) if the host did not answer in time.
%   @error python_error(Class, Message) if serving failed in Python.

read_table(Robot, Table) :-
    read_table(Robot, Table, []).

read_table(Robot, Table, Options) :-
    table_request(read_table(Robot), read_table/3, Options, Table).

%!  read_visits(+Robot, -Table) is det.
%!  read_visits(+Robot, -Table, +Options) is det.
%
%   As read_table/3 for the visit counts of Robot: Table is
%   qtable(Shape, Values) with the counts as floats.

read_visits(Robot, Table) :-
    read_visits(Robot, Table, []).

read_visits(Robot, Table, Options) :-
    table_request(read_visits(Robot), read_visits/3, Options, Table).

%!  read_table_and_visits(+Robot, -Table, -Visits) is det.
%!  read_table_and_visits(+Robot, -Table, -Visits, +Options) is det.
%
%   Table and Visits (as read_table/3 and read_visits/3) taken in the same
%   pause between two learning steps, so that they belong together (e.g.
%   for visit-weighted aggregation).

read_table_and_visits(Robot, Table, Visits) :-
    read_table_and_visits(Robot, Table, Visits, []).

read_table_and_visits(Robot, Table, Visits, Options) :-
    PI = read_table_and_visits/4,
    checked_request(table, Robot, Options),
    bridge_call(Robot, read_table_and_visits(Robot), PI, Options, Reply),
    (   Reply = tables(table(QShape, QData), table(VShape, VData))
    ->  decode_table(QShape, QData, Options, Table),
        decode_table(VShape, VData, Options, Visits)
    ;   reply_error(Reply, PI)
    ).

table_request(Op, PI, Options, Table) :-
    arg(1, Op, Robot),
    checked_request(table, Robot, Options),
    bridge_call(Robot, Op, PI, Options, Reply),
    (   Reply = table(Shape, Data)
    ->  decode_table(Shape, Data, Options, Table)
    ;   reply_error(Reply, PI)
    ).

%   checked_request(+Kind, +Robot, +Options): the checks of every request
%   for Robot's Kind (table or params).
checked_request(Kind, Robot, Options) :-
    must_be(atomic, Robot),
    must_be(list, Options),
    registered(Robot),
    offers(Kind, Robot).

decode_table(Shape, Data, Options, qtable(Shape, Values)) :-
    read_values(Data, Options, Values),
    check_size(Shape, Values).

%   With the option values(packed), fts data stay packed (checked whole
%   by the caller's vector_length/2, float_vectors.pl), else they are
%   decoded into a list.
read_values(Data, Options, Values) :-
    (   memberchk(values(packed), Options),
        packed_vector(Data)
    ->  Values = Data
    ;   decode_values(Data, Values)
    ).

check_size(Shape, Values) :-
    check_shape(Shape),
    Shape = [NS, NA],
    N is NS*NA,
    vector_length(Values, Len),
    (   Len =:= N
    ->  true
    ;   domain_error(qtable_size(N), Len)
    ).

%!  read_params(+Robot, -Params) is det.
%!  read_params(+Robot, -Params, +Options) is det.
%
%   Params is params(Layout, Samples, Values): a snapshot of Robot's
%   learnable parameters taken by the host between two learning steps,
%   Values a flat list of floats in the order of Layout (Name-Dims
%   blocks, each row-major) and Samples the number of steps the learner
%   has learnt from (an integer >= 0, the FedAvg weight). Options as
%   read_table/3.
%
%   @error existence_error(robot, Robot) if Robot is not registered here.
%   @error existence_error(params, Robot) if Robot offers no parameters.
%   @error timeout_error(bridge, Robot) if the host did not answer in time.
%   @error python_error(Class, Message) if serving failed in Python.

read_params(Robot, Params) :-
    read_params(Robot, Params, []).

read_params(Robot, Params, Options) :-
    PI = read_params/3,
    checked_request(params, Robot, Options),
    bridge_call(Robot, read_params(Robot), PI, Options, Reply),
    (   Reply = params(Layout, Samples, Data)
    ->  read_values(Data, Options, Values),
        layout_size(Layout, N),
        vector_length(Values, Len),
        (   Len =:= N
        ->  Params = params(Layout, Samples, Values)
        ;   domain_error(params_size(N), Len)
        )
    ;   reply_error(Reply, PI)
    ).

%!  write_table(+Robot, +Table) is det.
%!  write_table(+Robot, +Table, +Options) is det.
%
%   Replace Robot's Q-table with Table = qtable(Shape, Values). Shape must
%   be the registered shape and Values NStates*NActions finite numbers
%   (integers are converted to floats); the host checks that where the
%   table enters Python. If anything is wrong the robot's table is left
%   unchanged. Options: timeout(Seconds); every other option Name(Value)
%   with an atomic Value (e.g. round(3), agent(dfrl_q), epoch(1)) is
%   handed to the host with the write, which records where it came from.
%
%   @error existence_error(robot, Robot) if Robot is not registered here.
%   @error type_error(qtable, Culprit) if Table is not qtable(Shape,
%   Values); Culprit is Table abbreviated, never a whole table.
%   @error type_error(list, Culprit) if Values is no list (nor packed),
%   Culprit abbreviated likewise.
%   @error type_error(number, X) for a non-number in Values.
%   @error domain_error(shape(Registered), Shape) on a shape mismatch.
%   @error domain_error(qtable_size(N), Len) if Values has Len elements.
%   @error domain_error(finite_float, X) for an infinite or NaN value.
%   @error timeout_error(bridge, Robot) if the host did not answer in time.

write_table(Robot, Table) :-
    write_table(Robot, Table, []).

write_table(Robot, Table, Options) :-
    write_checked(table, Robot, Table, write_table/3, Options).

%!  write_params(+Robot, +Params) is det.
%!  write_params(+Robot, +Params, +Options) is det.
%
%   Replace Robot's parameters with Params = params(Layout, Values).
%   Layout must be the registered layout and Values as many finite
%   numbers as it holds; checked and recorded as write_table/3 does.
%
%   @error existence_error(params, Robot) if Robot offers no parameters.
%   @error type_error(params, Culprit) if Params is not params(Layout, Values).
%   @error domain_error(param_layout(Registered), Layout) on a layout mismatch.
%   @error domain_error(params_size(N), Len) if Values has Len elements.
%   Else as write_table/3.

write_params(Robot, Params) :-
    write_params(Robot, Params, []).

write_params(Robot, Params, Options) :-
    write_checked(params, Robot, Params, write_params/3, Options).

%   write_checked(+Kind, +Robot, +Item, +PI, +Options): the one write path
%   of tables (Kind table, Item qtable(Shape, Values)) and parameters
%   (Kind params, Item params(Layout, Values)): the request's checks, the
%   item's form, then the write request write_table(Robot, Shape, Data,
%   Origin) or write_params(Robot, Layout, Data, Origin).
write_checked(Kind, Robot, Item, PI, Options) :-
    checked_request(Kind, Robot, Options),
    item_parts(Kind, Item, Key, Values),
    must_be(ground, Key),
    must_be_values(Values),
    write_op(Kind, Robot, Key, Op0),
    write_values(Robot, Op0, Values, PI, Options).

item_parts(_, Item, _, _) :-
    var(Item),
    !,
    instantiation_error(Item).
item_parts(table, qtable(Shape, Values), Shape, Values) :- !.
item_parts(params, params(Layout, Values), Layout, Values) :- !.
item_parts(table, Item, _, _) :-
    abbreviated(Item, Culprit),
    type_error(qtable, Culprit).
item_parts(params, Item, _, _) :-
    abbreviated(Item, Culprit),
    type_error(params, Culprit).

write_op(table, Robot, Shape, write_table(Robot, Shape)).
write_op(params, Robot, Layout, write_params(Robot, Layout)).

must_be_values(Values) :-
    (   packed_vector(Values)
    ->  true
    ;   is_list(Values)
    ->  true
    ;   var(Values)
    ->  instantiation_error(Values)
    ;   abbreviated(Values, Culprit),
        type_error(list, Culprit)
    ).

%   write_values(+Robot, +Op0, +Values0, +PI, +Options)
%
%   Send the write Op0 extended with the encoded Values0 and the write's
%   origin (write_table(Robot, Shape, Data, Origin) or write_params(Robot,
%   Layout, Data, Origin)); throw the host's error. With fts the values are
%   first sent as they are (see fts_encoded/2): a type_error(float_list, _)
%   answer makes it convert them and ask again.

write_values(Robot, Op0, Values, PI, Options) :-
    packed_vector(Values),
    !,
    (   bridge_codec(fts)
    ->  vector_length(Values, _),       % checked whole before it is sent
        write_request(Robot, Op0, Values, PI, Options, Reply),
        (   Reply == ok
        ->  true
        ;   reply_error(Reply, PI)
        )
    ;   vector_floats(Values, List),
        write_values(Robot, Op0, List, PI, Options)
    ).
write_values(Robot, Op0, Values0, PI, Options) :-
    (   bridge_codec(fts),
        fts_encoded(Values0, Data0)
    ->  write_request(Robot, Op0, Data0, PI, Options, Reply0),
        (   Reply0 = error(type_error(float_list, _))
        ->  write_request_floats(Robot, Op0, Values0, PI, Options, Reply)
        ;   Reply = Reply0
        )
    ;   write_request_floats(Robot, Op0, Values0, PI, Options, Reply)
    ),
    (   Reply == ok
    ->  true
    ;   reply_error(Reply, PI)
    ).

write_request_floats(Robot, Op0, Values0, PI, Options, Reply) :-
    float_list(Values0, Values),
    bridge_codec(Codec),
    encode_values(Codec, Values, Data),
    write_request(Robot, Op0, Data, PI, Options, Reply).

write_request(Robot, Op0, Data, PI, Options, Reply) :-
    write_origin(Options, Origin),
    Op0 =.. [Name|Args0],
    append(Args0, [Data, Origin], Args),
    Op =.. [Name|Args],
    bridge_call(Robot, Op, PI, Options, Reply).

%   write_origin(+Options, -Origin): the options of a table write that say
%   where it comes from (contract K4: round(N), agent(Name), epoch(E), ...):
%   every Name(Value) option with an atomic Value except timeout/1. The
%   host records them with the write.

write_origin(Options, Origin) :-
    include(origin_option, Options, Origin).

origin_option(Option) :-
    compound(Option),
    compound_name_arity(Option, Name, 1),
    Name \== timeout,
    arg(1, Option, Value),
    atomic(Value).

reply_error(error(Formal), PI) :-
    !,
    throw(error(Formal, context(PI, _))).
reply_error(Reply, PI) :-
    throw(error(domain_error(bridge_reply, Reply), context(PI, _))).

