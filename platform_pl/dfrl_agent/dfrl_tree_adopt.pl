:- module(dfrl_tree_adopt,
          [ adopt_lost/10,              % +Node, +Ctx, +Module, +Self, +Position, +Phase,
                                        % +Lost, -Msgs, -Skips, -Stats
            adoption/4,                 % +Node, +Ctx, +Position, -Adopt
            lost_skips/4                % +Lost, +Ctx, +Why, -Skips
          ]).
:- use_module('../tartarus', [remote_agents/3]).
:- use_module(dfrl_tree_msg, [tree_post/4, tree_wait/6, tree_poll/6]).
:- use_module(dfrl_tree_copies, [tree_children/4, tree_subtree/4, tree_spawn/11]).
:- autoload(library(lists), [nth0/3, append/3, member/2]).
:- autoload(library(apply), [foldl/4]).

/** <module> Adopting the children of a tree copy lost in the round (dfrl_tree.pl)

A copy whose child X is lost in the round (its node stops answering or
no longer holds it) skips X's robot and offers itself as the parent of
X's children: it asks the stop of each child C of X in the tree for the
copy X sent there (named X's name and _; not one still staged there,
whose move X's loss cut off) and posts it adopt(C, Address,
Name) (adopt(C, Address, Name, Table) once the table goes down); a stop
without such a copy (X was lost before it sent one) gets a new copy
while the items go up (once the table goes down, its subtree is
skipped). A child whose stop does not answer is skipped and its own
children are offered the same. A copy that finds its parent lost
(its post up fails, or its parent is gone while it waits for the table)
waits up to three skip times for such an offer (adoption/4) and then
sends its subtree up to the adopter (or, with a table, writes it down
its subtree and reports there), else purges itself without writing. An
adopted copy lost in turn is lost with its whole subtree: adoption is
tried once per lost copy, not again for the adopted. So a copy lost inside a round costs its own robot only,
when its children are alive.
*/

%!  adopt_lost(+Node, +Ctx, +Module, +Self, +Position, +Phase, +Lost, -Msgs,
%!             -Skips, -Stats) is det.
%
%   The copy Self (module Module) at Position on Node adopts the children
%   of its Lost kids (kid(Position, Address, Name)) in Phase `up`
%   (waiting for their items) or down(Table) (waiting for their
%   reports). Msgs are the messages of the adopted (up/5 or done/3),
%   Skips the robots skipped, Stats what new copies cost.

%   (10 arguments: a fold over the lost copies with three accumulator pairs)
adopt_lost(_, _, _, _, _, _, [], [], [], stats(0, 0, 0)) :- !.
adopt_lost(Node, Ctx, M, Self, P, Phase, Lost, Msgs, Skips, Stats) :-
    Ctx = ctx(_, Order, K, info(_, _, _, _, _, _, SkipAfter, _)),
    length(Order, N),
    nth0(P, Order, _-stop(PH, PP, _)),
    atom_string(Self, SelfName),
    foldl(lost_one(Order, K, N), Lost, []-[], Skips0-Offer),
    foldl(offer(Ctx, parent(PH:PP, SelfName), Phase, SkipAfter, K, N), Offer,
          o([], Skips0, []), o(Peers0, Skips1, Fresh)),
    tree_spawn(Fresh, M, Self, Ctx, P, Peers0, Peers, Skips1, Skips2,
               stats(0, 0, 0), Stats),
    (   Phase == up -> Kind = up ; Kind = done ),
    tree_wait(Node, Ctx, Kind, Peers, Msgs, Lost1),
    lost_skips(Lost1, Ctx, "adopted, then lost", Skips3),
    append(Skips2, Skips3, Skips).

lost_one(Order, K, N, kid(X, Address, Name), S0-O0, S-O) :-
    nth0(X, Order, _-stop(_, _, Robot)),
    format(string(Text), "tree clone at ~w lost; its children were adopted", [Address]),
    append(S0, [skip(Robot, Text)], S),
    tree_children(X, K, N, Cs),
    format(atom(Prefix), '~w_', [Name]),        % the names of the lost copy's copies
    findall(C-Prefix, member(C, Cs), New),
    append(O0, New, O).

%   Offer the copy at C's stop (found by its name) to adopt it. A stop
%   without one gets a new copy while the items go up (afterwards its
%   subtree is skipped); a stop that does not answer is skipped and its
%   children are offered instead.
%   (9 arguments: one step of adopt_lost/10's fold (an accumulator pair of o/3))
offer(Ctx, parent(To, Name), Phase, SkipAfter, K, N, C-Prefix, o(P0, S0, F0), o(P, S, F)) :-
    Ctx = ctx(Key, Order, _, _),
    nth0(C, Order, _-stop(H, Port, Robot)),
    T is max(0.5, SkipAfter),
    (   catch(remote_agents(H:Port, Agents, [connect_timeout(T), reply_timeout(T)]), _, fail)
    ->  (   member(agent(Copy, _, _, Status), Agents),
            Status \== staged,             % staged: its move was cut off with X
            sub_atom(Copy, 0, _, _, Prefix)
        ->  (   Phase = down(Final)
            ->  Body = adopt(C, To, Name, Final)
            ;   Body = adopt(C, To, Name)
            ),
            (   tree_post(H:Port, Key, Body, SkipAfter)
            ->  append(P0, [kid(C, H:Port, Copy)], P), S = S0, F = F0
            ;   lost_skips([kid(C, H:Port, Copy)], Ctx, "did not take its adoption", More),
                append(S0, More, S), P = P0, F = F0
            )
        ;   Phase == up
        ->  append(F0, [C], F), P = P0, S = S0
        ;   lost_skips([kid(C, H:Port, none)], Ctx, "had no copy when the table came down",
                       More),
            append(S0, More, S), P = P0, F = F0
        )
    ;   format(string(Text), "its tree parent was lost and its stop ~w:~w did not answer",
               [H, Port]),
        append(S0, [skip(Robot, Text)], S1),
        tree_children(C, K, N, Cs),
        findall(G-Prefix, member(G, Cs), Gs),
        foldl(offer(Ctx, parent(To, Name), Phase, SkipAfter, K, N), Gs,
              o(P0, S1, F0), o(P, S, F))
    ).

%!  adoption(+Node, +Ctx, +Position, -Adopt) is semidet.
%
%   The copy at Position, whose parent is lost, takes the offer Adopt
%   (adopt(Position, Address, Name) or adopt(Position, Address, Name,
%   Table)) that comes to Node within three skip times; fails if none
%   does.

adoption(Node, Ctx, P, Adopt) :-
    Ctx = ctx(Key, _, _, info(_, _, _, _, _, _, SkipAfter, _)),
    get_time(T0),
    Deadline is T0 + 3 * SkipAfter,
    tree_poll(Node, Key, [adopt], [kid(P, _, _)], Deadline, Adopt).

%!  lost_skips(+Lost, +Ctx, +Why, -Skips) is det.
%
%   Skips are the robots of the subtrees of the Lost copies, with Why.

lost_skips(Lost, ctx(_, Order, K, _), Why, Skips) :-
    length(Order, N),
    findall(skip(Robot, Text),
            ( member(kid(C, Address, _), Lost),
              tree_subtree(C, K, N, Sub),
              member(Q, Sub),
              nth0(Q, Order, _-stop(_, _, Robot)),
              format(string(Text), "tree clone at ~w ~w", [Address, Why]) ),
            Skips).
