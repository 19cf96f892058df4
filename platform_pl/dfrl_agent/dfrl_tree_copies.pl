:- module(dfrl_tree_copies,
          [ tree_children/4,            % +Position, +Fanout, +Size, -Children
            tree_subtree/4,             % +Position, +Fanout, +Size, -Positions
            tree_spawn/11,              % +Children, +Module, +Self, +Ctx, +Position,
                                        % +Kids0, -Kids, +Skips0, -Skips, +Stats0, -Stats
            tree_go_to_stop/3,          % +Module, +Self, +Role
            add_stats/3                 % +Stats0, +Stats1, -Stats
          ]).
:- use_module('../tartarus', [current_node/1, node_property/2, purge_agent/1]).
:- use_module('../migration', [agent_clone/4, agent_move/3]).
:- use_module('../platform_errors', [message_text/2]).
:- use_module(dfrl_tree_msg, [tree_note/3, tree_poll/6]).
:- autoload(library(lists), [nth0/3, append/3, member/2, memberchk/2, numlist/3]).
:- autoload(library(apply), [foldl/4, maplist/3, exclude/3]).
:- autoload(library(debug), [debug/3]).

/** <module> The copies of a tree round (dfrl_tree.pl): where they go, how they get there

The shape of the tree (position P has the children K*P+1 ... K*P+K of
the N positions), and a parent sending a copy of itself to each of its
children's stops at once. Ctx is the round's context ctx(Key, Order, K,
Info) (dfrl_tree.pl), a copy's role role(Ctx, Position, ParentAddress,
ParentName) and, while it still has to move to its stop, role(Ctx,
Position, ParentAddress, ParentName, go(Address)); the role travels as
the agent's payload fact dfrl_tree_role(Agent, Role). Stats are
stats(Hops, Bytes, Retries).
*/

%!  tree_children(+Position, +Fanout, +Size, -Children) is det.
%
%   Children are the positions below Position in a tree of Size
%   positions with Fanout children each.

tree_children(P, K, N, Cs) :-
    From is K*P + 1,
    To is min(K*P + K, N - 1),
    (   From =< To -> numlist(From, To, Cs) ; Cs = [] ).

%!  tree_subtree(+Position, +Fanout, +Size, -Positions) is det.
%
%   Positions are Position and all positions below it.

tree_subtree(P, K, N, [P|Below]) :-
    tree_children(P, K, N, Cs),
    subtrees(Cs, K, N, Below).

subtrees([], _, _, []).
subtrees([C|Cs], K, N, Positions) :-
    tree_subtree(C, K, N, Sub),
    subtrees(Cs, K, N, Rest),
    append(Sub, Rest, Positions).


%!  tree_spawn(+Children, +Module, +Self, +Ctx, +Position, +Kids0, -Kids,
%!             +Skips0, -Skips, +Stats0, -Stats) is det.
%
%   Self (its module Module) at Position sends a copy to each of
%   Children; Kids are the copies that got there, kid(Child, Address,
%   Name), Skips the children skipped, skip(Robot, Text) (their children
%   got copies instead), Stats what it cost.

%   Send a copy to each child's stop, all at once: a copy is cloned on
%   this node (no network), with its role and the stop to go to, and moves
%   itself there in its own thread; each says here whether it got there
%   (moved/failed). A child that cannot be reached is skipped and its
%   children are sent copies instead.
%   (11 arguments: a fold over the children with three accumulator pairs)
tree_spawn([], _, _, _, _, Kids, Kids, Skips, Skips, St, St) :- !.
tree_spawn(Cs, M, Self, Ctx, P, Kids0, Kids, Skips0, Skips, St0, St) :-
    Ctx = ctx(Key, Order, K, info(_, _, _, _, _, _, SkipAfter, _)),
    nth0(P, Order, _-stop(PH, PP, _)),
    atom_string(Self, SelfName),
    current_node(Node),
    node_property(Node, address(Here)),
    foldl(local_copy(M, Self, Ctx, Here, PH:PP, SelfName), Cs, [], Copies),
    get_time(T0),
    Deadline is T0 + SkipAfter + 2,
    maplist(waiting, Copies, Waiting),
    await_moves(Node, Key, Waiting, Deadline, Outcomes),
    length(Order, N),
    foldl(outcome(Ctx, N, K, Copies), Outcomes,
          t(Kids0, Skips0, St0, []), t(Kids1, Skips1, St1, Adopted)),
    tree_spawn(Adopted, M, Self, Ctx, P, Kids1, Kids, Skips1, Skips, St1, St).

waiting(C-_, kid(C, none, none)).

%   A copy of Self on this node with the role of child C (go(Address):
%   it moves itself to C's stop first); failed(C, Text, 0) if it cannot
%   even be made.
%   (9 arguments: a copy's place in the tree and an accumulator pair)
local_copy(M, Self, Ctx, Here, Parent, SelfName, C, Copies0, Copies) :-
    Ctx = ctx(Key, Order, _, _),
    nth0(C, Order, _-stop(H, Port, _)),
    Role = role(Ctx, C, Parent, SelfName, go(H:Port)),
    setup_call_cleanup(assertz(M:dfrl_tree_role(Self, Role)),
                       once(catch(agent_clone(Self, Here, Copy, []), E, true)),
                       retractall(M:dfrl_tree_role(Self, _))),
    (   var(E)
    ->  append(Copies0, [C-Copy], Copies)
    ;   message_text(E, Text),
        current_node(Node),
        tree_note(Node, Key, failed(C, Text, 0)),
        append(Copies0, [C-none], Copies)
    ).

await_moves(_, _, [], _, []) :- !.
await_moves(Node, Key, Waiting, Deadline, Outcomes) :-
    (   tree_poll(Node, Key, [moved, failed], Waiting, Deadline, Msg)
    ->  arg(1, Msg, C),
        exclude(kid_at(C), Waiting, Waiting1),
        Outcomes = [Msg|Msgs],
        await_moves(Node, Key, Waiting1, Deadline, Msgs)
    ;   findall(failed(C, "its copy neither moved nor failed in time", 0),
                member(kid(C, _, _), Waiting), Outcomes)
    ).

kid_at(C, kid(C, _, _)).

outcome(Ctx, _, _, Copies, moved(C, R), t(Kids0, Sk, St0, Ad), t(Kids, Sk, St, Ad)) :-
    Ctx = ctx(_, Order, _, _),
    nth0(C, Order, _-stop(H, Port, _)),
    memberchk(C-Copy, Copies),
    append(Kids0, [kid(C, H:Port, Copy)], Kids),
    add_stats(St0, stats(1, 0, R), St).
outcome(Ctx, N, K, _, failed(C, Text0, R), t(Kids, Sk0, St0, Ad0), t(Kids, Sk, St, Ad)) :-
    Ctx = ctx(_, Order, _, info(_, _, _, _, _, _, SkipAfter, _)),
    nth0(C, Order, _-stop(H, Port, Robot)),
    format(string(Text), "~w (a tree clone; skip_after ~w s)", [Text0, SkipAfter]),
    print_message(warning, format("dfrl: skipping stop ~w:~w: ~w", [H, Port, Text])),
    append(Sk0, [skip(Robot, Text)], Sk),
    add_stats(St0, stats(0, 0, R), St),
    tree_children(C, K, N, Grand),
    append(Ad0, Grand, Ad).

%   The copy's move to its stop (role go(Address)), with the agent's
%   retries within its skip time; the outcome is left on this node for
%   the parent.
tree_go_to_stop(M, Self, role(Ctx, C, Parent, ParentName, go(Address))) :-
    Ctx = ctx(Key, _, _, info(_, _, _, _, _, _, SkipAfter, retry(Tries, Backoff))),
    current_node(Node),
    assertz(M:dfrl_tree_role(Self, role(Ctx, C, Parent, ParentName))),
    get_time(T0),
    Deadline is T0 + SkipAfter,
    attempt_move(Self, Address, Tries, Backoff, Deadline, 0, Result),
    debug(dfrl(tree), '~w to ~w: ~p', [Self, Address, Result]),
    (   Result = moved(R)
    ->  tree_note(Node, Key, moved(C, R))
    ;   Result = failed(E, R),
        get_time(T1),
        Waited is T1 - T0,
        message_text(E, Text0),
        format(string(Text), "~w (skipped after ~2f s)", [Text0, Waited]),
        tree_note(Node, Key, failed(C, Text, R)),
        catch(purge_agent(Self), _, true)
    ).

attempt_move(Self, Address, Tries, Backoff, Deadline, R, Result) :-
    get_time(Now),
    Left is max(0.1, Deadline - Now),
    catch(agent_move(Self, Address, [connect_timeout(Left), reply_timeout(Left)]), E, true),
    (   var(E)
    ->  Result = moved(R)
    ;   R < Tries,
        \+ E = error(permission_error(_, _, _), _),
        Wait is Backoff * 2**R,
        get_time(Now1),
        Now1 + Wait < Deadline
    ->  sleep(Wait),
        R1 is R + 1,
        attempt_move(Self, Address, Tries, Backoff, Deadline, R1, Result)
    ;   Result = failed(E, R)
    ).


%!  tree_go_to_stop(+Module, +Self, +Role) is det.
%
%   What a new copy does first (Role ends in go(Address)): move to its
%   stop, see above.

%!  add_stats(+Stats0, +Stats1, -Stats) is det.
%
%   Stats is the sum of the costs Stats0 and Stats1.

add_stats(stats(H0, B0, R0), stats(H1, B1, R1), stats(H, B, R)) :-
    H is H0 + H1, B is B0 + B1, R is R0 + R1.
