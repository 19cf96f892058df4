:- module(dfrl_round_state,
          [ new_round/3,                % +Round, +Origin, -State
            get_state/3,                % +Module, +Agent, -State
            put_state/3,                % +Module, +Agent, +State
            pack_state/2,               % +State, -Packed
            unpack_state/2,             % +Packed, -State
            replace_fact/2,             % +Module, +Fact
            skip_robot/4,               % +Robot, +Error, +State0, -State
            capped_text/2,              % +Text, -Capped
            method_failed/3,            % +Result, +State0, -State
            fold_item/6,                % +Method, +Robot, +Shape, +Item, +State0, -State
            print_capped_warning/1,     % +Error
            add_retries/3,              % +Retries, +State0, -State
            advance_to/3                % +Index, +State0, -State
          ]).
:- use_module('../platform_errors', [message_text/2]).
:- use_module(dfrl_aggregation, [aggregate_fold/5, fold_hook/3, method_call/3]).
:- use_module(dfrl_round_log, [log_text/2]).
:- autoload(library(lists), [append/3, memberchk/2, sum_list/2]).
:- autoload(library(apply), [maplist/2]).
:- use_module('../float_vectors', [vector_length/2, packed_vector/1]).
:- use_module('../fast_term_check', [fast_term_decode/3]).

/** <module> The round state of the dFRL agent (dfrl_agent.pl)

Where the agent is in its round, as a dict that travels with it as the
payload fact dfrl_state(Agent, State) in the agent's own module:

```
state{round, phase, index, origin, acc, visited, skipped, retries,
      hops, bytes, start, stop}          (and error, if the method failed)
```

`phase` is forward, backward or home (looking for the stop where the
round starts), `index` the stop of the itinerary the agent is at (or
goes to), `origin` the stop where the round started, `acc` the
aggregate (none before the first table and after a failed method),
`visited` the robots aggregated, `skipped` a list of skip(Robot, Text),
`retries`, `hops` and `bytes` what the round's moves cost, `start` the
time the round started and `stop` whether a stop command ends it.

The aggregate travels packed: a string is copied, asserted and sent as
one block, where a list of 20,000 floats costs milliseconds at each of
those steps. An aggregate of packed vectors (float_vectors.pl: the
tables as the Python bridge gives them) is packed already and stays as
it is; one that holds lists (a host that gives lists, a method of its
own) travels as one fast_term_serialized/2 string and is unpacked only
where the agent works on it (get_state/3).

The agent's handler runs in the agent's own module, so the facts the
predicates here replace in it are the agent writing its own state.
*/

%!  new_round(+Round, +Origin, -State) is det.
%
%   State is the state of round Round starting at stop Origin, in the
%   phase forward, nothing aggregated, visited, skipped or moved yet.

new_round(Round, Origin,
          state{round:Round, phase:forward, index:Origin, origin:Origin,
                acc:none, visited:[], skipped:[], retries:0, hops:0, bytes:0,
                start:0, stop:false}).

%!  get_state(+Module, +Agent, -State) is det.
%
%   State is Agent's round state, from its fact dfrl_state/2 in its
%   module Module, with the aggregate unpacked.

get_state(M, Agent, S) :-
    M:dfrl_state(Agent, S0),
    unpack_state(S0, S).

%!  unpack_state(+Packed, -State) is det.
%
%   State is the state Packed with its aggregate unpacked.

unpack_state(S0, S) :-
    get_dict(acc, S0, Packed),
    unpack(Packed, Acc),
    put_dict(acc, S0, Acc, S).

%!  put_state(+Module, +Agent, +State) is det.
%
%   Replace Agent's fact dfrl_state/2 in its module Module by State,
%   its aggregate packed.

put_state(M, Agent, S) :-
    pack_state(S, Packed),
    replace_fact(M, dfrl_state(Agent, Packed)).

%!  pack_state(+State, -Packed) is det.
%
%   Packed is State with its aggregate packed (as it travels): an
%   aggregate that holds a long list becomes one string (serialised);
%   one whose values are packed vectors already (float_vectors.pl, how
%   the agent reads tables from a host that gives them) stays as it is,
%   as cheap to store and to send.

pack_state(S0, S) :-
    get_dict(acc, S0, Acc),
    pack(Acc, Packed),
    put_dict(acc, S0, Packed, S).

pack(none, none) :- !.
pack(packed(S), packed(S)) :- !.
pack(Acc, Acc) :-
    compact(Acc),
    !.
pack(Acc, packed(String)) :-
    fast_term_serialized(Acc, String).

%   No list of more than 64 elements in T.
compact(T) :-
    (   is_list(T)
    ->  length(T, N),
        N =< 64,
        maplist(compact, T)
    ;   compound(T)
    ->  compound_name_arguments(T, _, Args),
        maplist(compact, Args)
    ;   true
    ).

unpack(none, none) :- !.
unpack(packed(String), Acc) :-            % it came with the agent: checked
    !,
    fast_term_decode(String, Acc, []).
unpack(Acc, Acc).

%!  replace_fact(+Module, +Fact) is det.
%
%   Fact is Name(Agent, Value): it replaces every Name(Agent, _) fact in
%   the agent's module Module.

replace_fact(M, Fact) :-
    functor(Fact, F, 2),
    arg(1, Fact, Agent),
    functor(Old, F, 2),
    arg(1, Old, Agent),
    retractall(M:Old),
    assertz(M:Fact).

%!  skip_robot(+Robot, +Error, +State0, -State) is det.
%
%   Record in the round state that Robot did not take part (once per
%   robot and round). Error is an error term or reason(Text); the log
%   gets it as text.

skip_robot(Robot, Error, S0, S) :-
    get_dict(skipped, S0, Skipped0),
    (   memberchk(skip(Robot, _), Skipped0)
    ->  S = S0
    ;   (   Error = reason(Text0)
        ->  log_text(Text0, Text1)
        ;   message_text(Error, Text1)
        ),
        capped_text(Text1, Text),
        append(Skipped0, [skip(Robot, Text)], Skipped),
        put_dict(skipped, S0, Skipped, S)
    ).

%!  capped_text(+Text, -Capped) is det.
%
%   Capped is Text cut to its first 300 characters (and "..." said),
%   so that a refusal whose message holds a whole table (a robot's
%   type error on the values it was sent, say) does not carry it into
%   the round log, rounds.csv and the node's warnings.

capped_text(Text, Capped) :-
    (   string_length(Text, L), L > 300
    ->  sub_string(Text, 0, 300, _, Head),
        string_concat(Head, "... (cut)", Capped)
    ;   Capped = Text
    ).

%!  method_failed(+Result, +State0, -State) is det.
%
%   The aggregation method failed with Result = error(Text) (see
%   dfrl_aggregation:method_call/3): say so, keep the error in the state
%   (logged with the round) and drop the aggregate, so that no robot is
%   written this round.

method_failed(error(Error), S0, S) :-
    print_message(error, format("dfrl: aggregation method: ~w; round aborted, \c
                                 no table is written", [Error])),
    put_dict(_{error:Error, acc:none}, S0, S).

%!  fold_item(+Method, +Robot, +Shape, +Item, +State0, -State) is det.
%
%   Fold Item, the table or parameters of Robot (of Shape, checked to fit
%   the aggregate), into the aggregate of State0 with Method, and count
%   Robot visited; a failure of the method is method_failed/3's (chain
%   and tree pass alike).

fold_item(Method, Robot, Shape, Item, S0, S) :-
    get_dict(acc, S0, Acc0),
    fold_hook(Acc0, Method, Hook),
    method_call(aggregate_fold(Method, Acc0, Shape, Item, Acc1), Hook, Result),
    (   Result == ok
    ->  get_dict(visited, S0, V0),
        append(V0, [Robot], V),
        put_dict(_{acc:Acc1, visited:V}, S0, S)
    ;   method_failed(Result, S0, S)
    ).

%!  print_capped_warning(+Error) is det.
%
%   Print Error as a warning, its text capped as capped_text/2 does.

print_capped_warning(Error) :-
    message_text(Error, Text0),
    capped_text(Text0, Text),
    print_message(warning, format("~w", [Text])).

%!  add_retries(+Retries, +State0, -State) is det.
%
%   Count Retries more moves tried again in the round.

add_retries(R, S0, S) :-
    get_dict(retries, S0, R0),
    R1 is R0 + R,
    put_dict(retries, S0, R1, S).

%!  advance_to(+Index, +State0, -State) is det.
%
%   State is State0 moved to the stop Index of the itinerary: one hop
%   more, and the aggregate's payload size added to the round's bytes.

advance_to(Next, S0, S) :-
    get_dict(acc, S0, Acc),
    carried_bytes(Acc, B),
    get_dict(hops, S0, Hops0),
    get_dict(bytes, S0, Bytes0),
    Hops is Hops0 + 1,
    Bytes is Bytes0 + B,
    put_dict(_{index:Next, hops:Hops, bytes:Bytes}, S0, S).

%   Payload size of the aggregate in bytes: 10 per float in the fast
%   serialisation used on the wire (an estimate, without the clauses).
%   (A list or packed, float_vectors.pl: the same bytes.)
carried_bytes(qtable(_, V), B) :- !, vector_length(V, N), B is 10 * N.
carried_bytes(acc(_, A), B) :- !, carried_bytes(A, B).
carried_bytes(Acc, B) :-
    (   compound(Acc), \+ packed_vector(Acc)
    ->  findall(N, ( arg(_, Acc, L), ( is_list(L) ; packed_vector(L) ),
                     vector_length(L, N) ), Ns),
        sum_list(Ns, Total),
        B is 10 * Total
    ;   B = 0
    ).
