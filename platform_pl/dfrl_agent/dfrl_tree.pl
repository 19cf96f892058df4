:- module(dfrl_tree,
          [ tree_round/5,               % +Module, +Agent, +Fanout, +State0, -State
            tree_fallback/6,            % +Module, +Agent, +Method, +Start, +Failed, -State
            tree_clone_role/3,          % +Module, +Agent, -Role
            tree_clone_run/3,           % +Module, +Agent, +Role
            tree_children/4,            % +Position, +Fanout, +Size, -Children
            tree_subtree/4              % +Position, +Fanout, +Size, -Positions
          ]).
:- use_module('../tartarus', [current_node/1, purge_agent/1, with_node/2]).
:- use_module(dfrl_tree_msg, [tree_post/4, tree_wait/6, tree_forget/2]).
:- use_module(dfrl_tree_adopt, [adopt_lost/10, adoption/4]).
:- use_module(dfrl_tree_copies,
              [ tree_children/4, tree_subtree/4, tree_spawn/11, tree_go_to_stop/3,
                add_stats/3 ]).
:- use_module(dfrl_lease, [lease_custody/3, lease_write_gate/2]).
:- use_module(dfrl_round_state,
              [ skip_robot/4, add_retries/3, print_capped_warning/1, method_failed/3,
                replace_fact/2, fold_item/6 ]).
:- use_module(dfrl_payload, [next_method/5, carried/3, itinerary_kind/3]).
:- use_module(dfrl_round_log, [log_control/5]).
:- use_module(dfrl_robot_io, [read_robot/5, write_robot/3, item_bytes/2]).
:- use_module(dfrl_aggregation,
              [ aggregate_fold/5, aggregate_finish/3, aggregate_fits/2,
                fold_hook/3, method_call/3, item_shape/2 ]).
:- use_module(dfrl_move, [skip_after/3]).
:- use_module('../platform_errors', [message_text/2]).
:- autoload(library(lists), [nth0/3, append/3, member/2, memberchk/2, subtract/3]).
:- autoload(library(apply), [foldl/4, maplist/3, include/3, exclude/3]).
:- autoload(library(debug), [debug/3]).
:- autoload(library(pairs), [pairs_keys/2]).
:- autoload(library(thread), [concurrent_maplist/3]).

/** <module> The tree itinerary of the dFRL agent: a round by clones

In a round of an agent whose itinerary is tree(Fanout) (dfrl_agent.pl,
payload fact dfrl_itinerary_of(Agent, tree(K))) the agent stays at the
stop where the round starts (the root) and clones itself over a K-ary
tree of the other stops, the root first and then the rest in itinerary
order, position P having the children K*P+1 ... K*P+K:

  1. out: each copy sends a copy of itself to each of its children's
     stops, all at once (dfrl_tree_copies.pl), then reads its own robot;
  2. up: each copy collects what its children send up, the items (the
     robots' tables) of their subtrees and the stops they skipped, and
     sends all of it, with its own, to its parent;
  3. the root folds the items with the agent's method in itinerary
     order, exactly as the chain's forward pass folds them, so a tree
     round gives bit for bit the table a chain round gives from the same
     tables, for every method (sums and weights are folded, never
     averages of partial averages);
  4. down: the root writes the table into its robot and sends it to its
     children, each copy writes it into its robot and sends it on;
  5. each copy reports the stops whose write failed to its parent and
     purges itself; the root ends the round (dfrl_agent:end_round) and
     logs it: `visited` are the robots folded, in itinerary order,
     `hops` the copies that reached their stops, `bytes` the items and
     tables sent.

A copy that cannot reach its stop (the stop is down) is tried as a move
is (the agent's retries with backoff, all within its skip time), then
the stop is skipped and its children get copies from the parent
instead: only the dead stop is missing from the round. A copy waiting
for a child (or for its parent) asks the other's node every skip time
whether it is still there; a child lost with its node has its whole
subtree skipped, with the reason, and a copy whose parent is lost purges
itself without writing. So every robot written in the round gets the
same table, and every robot not read or not written is listed in
`skipped` (as in a chain round, a robot read but not written stays in
`visited` too).

Clones carry no custody of their own: the root keeps the agent's lease
(dfrl_lease.pl) as a chain agent does between moves; a clone lost is a
subtree skipped for that round, never resurrected.

Copies talk through the platform event dfrl_tree_msg/3 posted to the
node of the stop the receiver is at (dfrl_tree_msg.pl), Key a string
naming the round (agent, epoch, round and a random part).
*/

		 /*******************************
		 *             ROOT		*
		 *******************************/

%!  tree_round(+Module, +Agent, +Fanout, +State0, -State) is det.
%
%   Run one round of Agent (its module Module) as the root of a tree of
%   fan-out Fanout, from the round state State0 (at its origin, the
%   round started); State is the state at its end.

tree_round(_, _, _, S0, S) :-
    get_dict(error, S0, _),             % the method does not apply: no reads
    !,
    S = S0.
tree_round(M, Agent, K, S0, S) :-
    current_node(Node),
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, Timeout)),
    M:dfrl_method_of(Agent, Method),
    carried(M, Agent, Carried),
    get_dict(origin, S0, Origin),
    get_dict(round, S0, Round),
    get_dict(skipped, S0, Skipped),
    findall(I-Stop,
            ( nth0(I, Itinerary, Stop), I =\= Origin,
              Stop = stop(_, _, R), \+ memberchk(skip(R, _), Skipped) ),
            Rest),
    nth0(Origin, Itinerary, Root),
    Order = [Origin-Root|Rest],
    lease_custody(Node, Agent, custody(Epoch, _, _)),
    skip_after(M, Agent, SkipAfter),
    retry_of(M, Agent, Retry),
    atom_string(Agent, Name),
    random_between(0, 0xffffffff, Nonce),
    format(string(Key), "~w/~w/~w/~16r", [Agent, Epoch, Round, Nonce]),
    Ctx = ctx(Key, Order, K, info(Name, Epoch, Round, Method, Carried, Timeout,
                                  SkipAfter, Retry)),
    call_cleanup(guarded_round(M, Agent, Ctx, S0, S),
                 tree_forget(Node, Key)).

%   A round that fails or raises (a fault of this code, not of a robot or
%   a node: those are skips) is logged with the error, nothing written
%   after it, and the agent goes on with its next round.
guarded_round(M, Agent, Ctx, S0, S) :-
    (   catch_with_backtrace(root_round(M, Agent, Ctx, S0, S1),    % errors only: the
                             error(F, C), E = error(F, C))          % platform's balls
    ->  true                                                        % (purge, bounds) stop it
    ;   E = failed
    ),
    (   var(E)
    ->  S = S1
    ;   (   E == failed -> Text = "the tree round failed" ; message_text(E, Text) ),
        print_message(error, format("dfrl: ~w: ~w", [Agent, Text])),
        put_dict(_{error:Text, acc:none}, S0, S)
    ).

root_round(M, Agent, Ctx, S0, S) :-
    out_pass(M, Agent, Ctx, 0, out(Items, Skips1, Stats1, Kids)),
    Ctx = ctx(_, _, _, info(_, _, _, Method, _, _, _, _)),
    msort(Items, Sorted),
    foldl(note_skip, Skips1, S0, S1),
    fold_items(Sorted, Method, S1, S2),
    get_dict(acc, S2, Acc),
    (   get_dict(error, S2, _)
    ->  Final = none, S3 = S2
    ;   method_call(aggregate_finish(Method, Acc, Final0), aggregate_final(Method), Result),
        (   Result == ok
        ->  Final = Final0, S3 = S2
        ;   method_failed(Result, S2, S3), Final = none
        )
    ),
    (   Final \== none,
        Sorted = [_],                   % nothing federated: nothing written
        M:dfrl_plan(Agent, plan([_, _|_], _, _, _, _))    % (dfrl_agent:alone/3)
    ->  Final1 = none,
        S3a = S3
    ;   Final \== none,
        \+ ( current_node(Node), lease_write_gate(Node, Agent) )
    ->  print_message(warning, format("dfrl: ~w: round not written: its lease could not be \c
                                       renewed (fenced)", [Agent])),
        Final1 = none,
        S3a = S3.put(fenced, true)
    ;   Final1 = Final,
        S3a = S3
    ),
    down_pass(Ctx, Agent, 0, Final1, Kids, Skips2, Stats2),
    foldl(note_skip, Skips2, S3a, S4),
    add_stats(Stats1, Stats2, stats(Hops, Bytes, Retries)),
    get_dict(hops, S4, H0), get_dict(bytes, S4, B0),
    H is H0 + Hops, B is B0 + Bytes,
    add_retries(Retries, S4, S5),
    put_dict(_{acc:Final1, hops:H, bytes:B}, S5, S).

note_skip(skip(Robot, Text), S0, S) :-
    skip_robot(Robot, reason(Text), S0, S).

%   Fold the items (I-Robot-Item, in itinerary order) as the chain's
%   forward pass does: an item that does not fit is skipped, a method
%   that fails aborts the round.
fold_items([], _, S, S).
fold_items([_-Robot-Item|Items], Method, S0, S) :-
    (   get_dict(error, S0, _)
    ->  S = S0
    ;   get_dict(acc, S0, Acc0),
        catch(( item_shape(Item, Shape), aggregate_fits(Acc0, Shape) ), E, true),
        (   nonvar(E)
        ->  print_capped_warning(E),
            skip_robot(Robot, E, S0, S1)
        ;   fold_item(Method, Robot, Shape, Item, S0, S1)
        ),
        fold_items(Items, Method, S1, S)
    ).

%!  tree_fallback(+Module, +Agent, +Method, +Start, +Failed, -State) is semidet.
%
%   A tree round whose method failed (the round began in state Start and
%   ended in Failed, which has an error) is run again at once with the
%   method it falls back to (as a chain round, dfrl_rounds.pl): its
%   copies read and write every robot again; the hops of both count.
%   Fails if the round did not fail, was a fallback already, or there is
%   no other method to fall back to.

tree_fallback(M, Agent, Method, S1, S2, S) :-
    get_dict(error, S2, Error),
    \+ get_dict(fallback, S1, _),
    carried(M, Agent, Carried),
    next_method(Method, Carried, S2, Next, _),
    Next \== Method,
    itinerary_kind(M, Agent, tree(K)),
    get_dict(round, S1, Round),
    print_message(warning,
                  format("dfrl: ~w round ~w: method ~w failed (~w); the tree round runs \c
                          again with ~w", [Agent, Round, Method, Error, Next])),
    replace_fact(M, dfrl_method_of(Agent, Next)),
    M:dfrl_plan(Agent, plan(_, _, _, Log, _)),
    log_control(Log, Agent, Round, fallback(Method, Next), applied),
    get_dict(hops, S2, Hops),
    get_dict(bytes, S2, Bytes),
    get_dict(retries, S2, Retries),
    (   del_dict(error, S1, _, S1a)         % the method did not apply at all
    ->  true
    ;   S1a = S1
    ),
    put_dict(_{hops:Hops, bytes:Bytes, retries:Retries,
               fallback:failed(Method, Error)}, S1a, S1b),
    tree_round(M, Agent, K, S1b, S).

		 /*******************************
		 *            CLONES		*
		 *******************************/

%!  tree_clone_role(+Module, +Agent, -Role) is semidet.
%
%   Agent (module Module) is a clone of a tree round with Role: take its
%   role fact (so that its own clones do not inherit it).

tree_clone_role(M, Agent, Role) :-
    catch(M:dfrl_tree_role(Agent, Role), _, fail),
    retractall(M:dfrl_tree_role(Agent, _)).

%!  tree_clone_run(+Module, +Agent, +Role) is det.
%
%   Run the clone Agent's part of the round, Role role(Ctx, Position,
%   Parent, ParentName), and purge it; or, with Role role(..., go(Address)),
%   first move it to its stop at Address.

tree_clone_run(M, Agent, Role) :-
    Role = role(_, _, _, _, go(_)),
    !,
    tree_go_to_stop(M, Agent, Role).
tree_clone_run(M, Agent, role(Ctx, P, Parent, ParentName)) :-
    Ctx = ctx(Key, _, _, info(_, _, _, _, _, _, SkipAfter, _)),
    current_node(Node),
    call_cleanup(( clone_part(M, Agent, Ctx, P, Parent, ParentName, SkipAfter, Node)
                 ->  true
                 ;   print_message(error, format("dfrl: tree clone ~w at position ~w \c
                                                  failed", [Agent, P]))
                 ),
                 ( tree_forget(Node, Key),
                   catch(purge_agent(Agent), _, true) )).

%   (8 arguments: a clone's place in the tree (context, position, parent) and its limits)
clone_part(M, Agent, Ctx, P, Parent, ParentName, SkipAfter, Node) :-
    Ctx = ctx(Key, _, _, _),
    out_pass(M, Agent, Ctx, P, out(Items, Skips, Stats0, Kids)),
    foldl(add_item_bytes, Items, 0, Bytes),
    add_stats(Stats0, stats(0, Bytes, 0), Stats),
    atom_string(Agent, Name),
    send_up(Node, Ctx, P, up(P, Items, Skips, Stats, Name), kid(P, Parent, ParentName), 3,
            Result),
    (   Result = down(Final, kid(_, To, _))
    ->  down_pass(Ctx, Agent, P, Final, Kids, Skips1, Stats1),
        ignore(tree_post(To, Key, done(P, Skips1, Stats1), SkipAfter))
    ;   print_message(warning, format("dfrl: tree clone ~w: its parent at ~w was lost \c
                                       and nobody adopted it; nothing written",
                                       [Agent, Parent]))
    ).

%   Send the subtree up to the parent and wait for the table; a parent
%   lost meanwhile is replaced by the copy that adopts this one (at most
%   Tries times; dfrl_tree_adopt.pl). Result is down(Table, Parent) or
%   orphan.
send_up(Node, Ctx, P, Up, Peer, Tries, Result) :-
    Ctx = ctx(Key, _, _, info(_, _, _, _, _, _, SkipAfter, _)),
    Peer = kid(_, To, _),
    (   tree_post(To, Key, Up, SkipAfter),
        tree_wait(Node, Ctx, down, [Peer], [down(P, Final)], _)
    ->  Result = down(Final, Peer)
    ;   debug(dfrl(tree), 'position ~w: parent ~w lost; waits for an adoption', [P, To]),
        Tries > 0,
        adoption(Node, Ctx, P, Adopt)
    ->  Tries1 is Tries - 1,
        (   Adopt = adopt(P, A, N, Final)
        ->  Result = down(Final, kid(P, A, N))
        ;   Adopt = adopt(P, A, N),
            send_up(Node, Ctx, P, Up, kid(P, A, N), Tries1, Result)
        )
    ;   Result = orphan
    ).

		 /*******************************
		 *        OUT, UP AND DOWN	*
		 *******************************/

%   out(Items, Skips, Stats, Kids): the items of P's subtree
%   (I-Robot-Item), the stops skipped in it, what it cost and P's
%   children that took part (kid(Position, Address, Name)).
out_pass(M, Self, Ctx, P, out(Items, Skips, Stats, Kids)) :-
    Ctx = ctx(_, Order, K, Info),
    Info = info(Root, Epoch, Round, Method, Carried, Timeout, _, _),
    length(Order, N),
    tree_children(P, K, N, Cs),
    tree_spawn(Cs, M, Self, Ctx, P, [], Kids0, [], Skips0, stats(0, 0, 0), Stats00),
    nth0(P, Order, I-stop(_, _, Robot)),
    atom_string(RootName, Root),
    Options = [timeout(Timeout), round(Round), agent(RootName), epoch(Epoch)],
    (   catch(read_robot(Carried, Method, Robot, Options, Item),   % errors only:
              error(F, C), E = error(F, C))                         % a purge ends it
    ->  (   var(E)
        ->  Own = [I-Robot-Item], OwnSkips = []
        ;   print_capped_warning(E),
            message_text(E, Text), Own = [], OwnSkips = [skip(Robot, Text)]
        )
    ;   Own = [], OwnSkips = [skip(Robot, "the robot could not be read")]
    ),
    current_node(Node),
    debug(dfrl(tree), '~w at ~w: read ~w, waits for ~p', [Self, P, Robot, Kids0]),
    tree_wait(Node, Ctx, up, Kids0, Msgs0, Lost),
    debug(dfrl(tree), '~w at ~w: up ~p, lost ~p', [Self, P, Msgs0, Lost]),
    adopt_lost(Node, Ctx, M, Self, P, up, Lost, Adopted, LostSkips, AdoptStats),
    append(Msgs0, Adopted, Msgs),
    maplist(kid_of(Order), Msgs, Kids),
    add_stats(Stats00, AdoptStats, Stats0),
    foldl(take_up, Msgs, Own-Stats0, Items-Stats),
    maplist(arg(3), Msgs, SkipLists),
    append([Skips0, OwnSkips, LostSkips|SkipLists], Skips).

add_item_bytes(_-_-Item, B0, B) :-
    item_bytes(Item, IB),
    B is B0 + IB.

kid_of(Order, up(C, _, _, _, Name), kid(C, H:P, Name)) :-
    nth0(C, Order, _-stop(H, P, _)).

take_up(up(_, Items, _, St, _), Items0-St0, Items1-St1) :-
    append(Items0, Items, Items1),
    add_stats(St0, St, St1).

%   Write the round's table into the robot of this stop (none: the round
%   was aborted, nothing is written).
write_own(_, _, none, []) :- !.
write_own(ctx(_, _, _, Info), Robot, Final, Skips) :-
    Info = info(Root, Epoch, Round, _, _, Timeout, _, _),
    atom_string(RootName, Root),
    catch(write_robot(Final, Robot, [timeout(Timeout), round(Round),
                                     agent(RootName), epoch(Epoch)]),
          error(F, C), E = error(F, C)),
    (   var(E)
    ->  Skips = []
    ;   print_capped_warning(E),
        message_text(E, Text),
        Skips = [skip(Robot, Text)]
    ).

%   Send the table down to the kids, write it into this stop's robot,
%   collect what the kids report back.
down_pass(Ctx, Self, P, Final, Kids, Skips, Stats) :-
    Ctx = ctx(Key, Order, _, info(_, _, _, _, _, _, SkipAfter, _)),
    item_bytes(Final, FB),
    current_node(Node),
    concurrent_maplist(send_down(Node, Key, Final, SkipAfter), Kids, Sent0),
    include(not_sent, Sent0, FailedPairs),
    pairs_keys(FailedPairs, Failed),
    length(Kids, NK), length(Failed, NF), Sent is NK - NF,
    nth0(P, Order, _-stop(_, _, Robot)),
    write_own(Ctx, Robot, Final, OwnSkips),
    subtract(Kids, Failed, Reached),
    current_node(Node),
    tree_wait(Node, Ctx, done, Reached, Msgs0, Lost),
    append(Failed, Lost, Gone),
    adopt_lost(Node, Ctx, none, Self, P, down(Final), Gone, Adopted, LostSkips, _),
    append(Msgs0, Adopted, Msgs),
    foldl(take_done, Msgs, []-stats(0, 0, 0), DoneSkips-Stats0),
    Bytes is FB * Sent,
    add_stats(Stats0, stats(0, Bytes, 0), Stats),
    append([OwnSkips, LostSkips, DoneSkips], Skips).

not_sent(_-false).

take_done(done(_, S, St), S0-T0, S1-T1) :-
    append(S0, S, S1),
    add_stats(T0, St, T1).

send_down(Node, Key, Final, SkipAfter, Kid, Kid-Sent) :-
    Kid = kid(C, Address, _),
    (   with_node(Node, tree_post(Address, Key, down(C, Final), SkipAfter))
    ->  Sent = true
    ;   Sent = false
    ).


		 /*******************************
		 *            HELPERS		*
		 *******************************/

retry_of(M, Agent, retry(R, B)) :-
    (   catch(M:dfrl_retry_of(Agent, retry(R, B)), _, fail) -> true ; R = 2, B = 0.2 ).
