:- module(platform_errors,
          [ transport_error/2,          % +Address, +Reason
            wire_error/1,               % +Reason
            message_text/2,             % +Message, -String
            inert_error/2,              % +Error0, -Error
            abbreviated/2               % +Term, -Short
          ]).
/** <module> Error terms of the agent platform and their messages

The platform throws only error(Formal, Context) terms. It reuses the ISO
formals where they fit (existence_error/2, permission_error/3, type_error/2,
domain_error/2) and adds:

  - transport_error(Address, Reason)
    Talking to the platform at Address failed: Reason is one of
    connect(Detail), timeout(Phase), closed(Phase) or protocol(Detail).
  - wire_error(Reason)
    A frame could not be read: bad_magic, bad_version(V),
    too_large(Size, Max), binary_not_allowed, syntax(Detail) or truncated.

and two permission errors with messages of their own:

  - permission_error(install, code, Culprit)
    Code from a peer was refused by the sandbox (code_safety.pl).
    Culprit is the offending goal, undefined(PI, Goal),
    unknown_call(Goal), clause_head(Head), directive(D), handler(H),
    data, M:Name/Arity (a platform predicate outside the agent API) or
    moved_hook(Old, New) (a hook of dfrl_agent that is in dfrl_aggregation
    now).
  - permission_error(post, event, Handler/Arity)
    A post named no event the agent declares.

Each has a prolog:error_message//1 clause, so the toplevel prints a
readable message.

An error term that a peer or mobile code made is printed only if it is
inert (inert_error/2): message translation takes a formal
format(Format, Args), and some messages take parts of their term as a
format, so a `~@` in it would call a goal of the sender's choosing
where the message is printed. A term with a `~` in any of its text is
shown as foreign_error(Text) instead, Text its quoted form.

An error that a remote platform answered with is rethrown here as
error(Formal, remote(Address)): the formal as the peer raised it (its
own context stays there) and, as context, the address of the platform
that raised it. A prolog:message_context//1 clause prints that address
after the message, e.g.

```
?- agent_post(127.0.0.1:7002, nobody, hello, x, []).
ERROR: agent `nobody' does not exist (at 127.0.0.1:7002)
```
*/

:- autoload(library(apply), [maplist/2]).

:- multifile prolog:error_message//1, prolog:message//1,
             prolog:message_context//1.

%!  transport_error(+Address, +Reason) is det.
%
%   Throw error(transport_error(Address, Reason), _).

transport_error(Address, Reason) :-
    throw(error(transport_error(Address, Reason), _)).

%!  wire_error(+Reason) is det.
%
%   Throw error(wire_error(Reason), _).

wire_error(Reason) :-
    throw(error(wire_error(Reason), _)).

%!  message_text(+Message, -Text:string) is det.
%
%   Text is Message (an error term or any message term) as
%   print_message/2 would print it, on one or more lines without the
%   `ERROR:`/`Warning:` prefix; a term without a translation is written
%   with ~p. For logs and replies that carry an error as text.

message_text(Message0, Text) :-
    inert_error(Message0, Message),
    (   catch('$messages':translate_message(Message, Lines, []), _, fail)
    ->  with_output_to(string(Text0),
                       print_message_lines(current_output, '', Lines)),
        split_string(Text0, "", "\n", [Text])
    ;   format(string(Text), '~p', [Message])
    ),
    !.

%!  abbreviated(+Term, -Short) is det.
%
%   Short is Term itself if it is small (64 cells), else its text with
%   at most 10 elements of a list and 200 characters shown: what a
%   message about a term that may hold a whole table says of it.

abbreviated(Term, Short) :-
    (   term_size(Term, Cells), Cells =< 64
    ->  Short = Term                    % small: the term itself
    ;   format(string(Text), "~W", [Term, [max_depth(10), quoted(true), portray(false)]]),
        (   string_length(Text, L), L > 200
        ->  sub_string(Text, 0, 200, _, Head),
            string_concat(Head, "...", Short)
        ;   Short = Text
        )
    ).

%!  inert_error(+Error0, -Error) is det.
%
%   Error is Error0 if no atom, string or code list in it holds a `~`
%   and it is acyclic; else error(foreign_error(Text), Context), Text a
%   string that writes Error0 quoted (to depth 10), Context the context
%   of Error0 if it is error(_, Context) with an inert Context.

inert_error(E0, E) :-
    (   inert(E0)
    ->  E = E0
    ;   format(string(Text), '~W', [E0, [quoted(true), max_depth(10)]]),
        (   nonvar(E0), E0 = error(_, Ctx0), inert(Ctx0)
        ->  Ctx = Ctx0
        ;   true
        ),
        E = error(foreign_error(Text), Ctx)
    ).

inert(T) :-
    acyclic_term(T),
    inert_(T).

inert_(T) :-
    (   var(T)
    ->  true
    ;   atom(T)
    ->  \+ sub_atom(T, _, _, _, '~')
    ;   string(T)
    ->  \+ sub_string(T, _, _, _, "~")
    ;   is_list(T), T = [_|_], maplist(integer, T)
    ->  \+ memberchk(0'~, T)
    ;   compound(T)
    ->  compound_name_arguments(T, _, Args),
        maplist(inert_, Args)
    ;   true
    ).

prolog:error_message(foreign_error(Text)) -->
    [ 'error from a peer or from mobile code: ~w'-[Text] ].

prolog:error_message(transport_error(Address, Reason)) -->
    [ 'Platform at ~p: '-[Address] ],
    transport_reason(Reason).
prolog:error_message(wire_error(Reason)) -->
    [ 'Malformed frame: ' ],
    wire_reason(Reason).

%   These clauses are tried on every error's context, which may be
%   partly unbound (context(_, _) once a catcher matched it): each
%   checks its context with ==/subsumes_term/2 and never binds it.
prolog:message_context(Context) -->
    { subsumes_term(context(node_start/3, weak_secret(_, _)), Context),
      Context = context(_, weak_secret(Bits, Need)),
      integer(Bits), integer(Need)
    },
    [ ': its weakest token has ~d bits of entropy; without TLS, '-[Bits],
      'a node reachable from the network needs ~d '-[Need],
      '(`dfrl secret` prints one), or insecure(true) / --insecure' ].
prolog:message_context(Context) -->
    { subsumes_term(remote(_), Context),
      Context = remote(Address),
      ground(Address)
    },
    [ ' (at ~w)'-[Address] ].

transport_reason(connect(Detail)) -->
    !, [ 'cannot connect (~p)'-[Detail] ].
transport_reason(timeout(Phase)) -->
    !, [ 'no answer in time (while ~w)'-[Phase] ].
transport_reason(closed(Phase)) -->
    !, [ 'connection closed by the peer (while ~w)'-[Phase] ].
transport_reason(protocol(Detail)) -->
    !, [ 'protocol violation (~p)'-[Detail] ].
transport_reason(Other) -->
    [ '~p'-[Other] ].

wire_reason(bad_magic) -->
    !, [ 'not a dfrl frame (bad magic bytes)' ].
wire_reason(bad_version(V)) -->
    !, [ 'unsupported protocol version ~w'-[V] ].
wire_reason(too_large(Size, Max)) -->
    !, [ 'frame of ~D bytes exceeds the limit of ~D bytes'-[Size, Max] ].
wire_reason(binary_not_allowed) -->
    !, [ 'binary frame on a connection that has not proved a token' ].
wire_reason(syntax(Detail)) -->
    !, [ 'unreadable term (~p)'-[Detail] ].
wire_reason(truncated) -->
    !, [ 'connection closed in the middle of a frame' ].
wire_reason(Other) -->
    [ '~p'-[Other] ].

prolog:message(dfrl(Message)) -->
    dfrl_message(Message).

dfrl_message(weak_token(Address, Bits)) -->
    [ 'dfrl platform ~w: a token of ~d bits is fine on loopback only; '-[Address, Bits],
      'other addresses need 128 (dfrl secret prints one) or TLS' ].
dfrl_message(open_node(Address)) -->
    [ 'dfrl platform ~w has no token: it is OPEN, any local user may '-[Address],
      'send it agents and code (give it a token: DFRL_TOKEN or --token-file)' ].
dfrl_message(token_on_command_line) -->
    [ '--token puts the token on the command line, where other users of ',
      'this host see it (ps); use --token-file FILE (mode 600) or the ',
      'environment variable DFRL_TOKEN' ].
dfrl_message(insecure_node(Address, Bits)) -->
    [ 'dfrl platform ~w is INSECURE: reachable from the network '-[Address],
      'with a token of ~d bits (128 needed) and no TLS'-[Bits] ].
dfrl_message(address_in_use(Host:Port)) -->
    [ 'port ~w on ~w is in use (another dfrl node or robot?); '-[Port, Host],
      'pick another --port (0: the OS chooses one) or stop what holds it' ].
dfrl_message(node_started(Node)) -->
    [ 'dfrl platform listening on ~w'-[Node] ].
dfrl_message(node_stopped(Node)) -->
    [ 'dfrl platform ~w stopped'-[Node] ].
dfrl_message(agent_crashed(Node, Agent, Error0)) -->
    { inert_error(Error0, Error) },
    [ 'Agent ~p on ~w stopped with an error: '-[Agent, Node] ],
    '$messages':translate_message(Error).
dfrl_message(connection_error(Node, Peer, Error0)) -->
    { inert_error(Error0, Error) },
    [ 'Platform ~w: request from ~p failed: '-[Node, Peer] ],
    '$messages':translate_message(Error).
dfrl_message(agent_in_doubt(Node, Agent, Source)) -->
    [ 'Platform ~w: migration of agent ~p from ~p was not confirmed; '-[Node, Agent, Source],
      'the agent is kept as in_doubt (see agent_resolve/2)'
    ].

%   Refused mobile code (code_safety.pl): the culprit says what.
prolog:error_message(permission_error(install, code, Culprit)) -->
    [ 'Refused mobile code: ' ],
    code_culprit(Culprit),
    [ ' (code from a peer runs in the sandbox: platform_pl/README.md, "Mobile code")' ].
prolog:error_message(permission_error(post, event, Handler/Arity)) -->
    [ 'No such event: ~q is not an event the agent declares '-[Handler/Arity],
      '(its events(List), or its own handler clauses)' ].

code_culprit(moved_hook(Old, New)) -->
    { ground(Old-New) },
    !, [ 'it uses ~q, which is ~q now: the aggregation hooks moved to '-[Old, New],
         'dfrl_aggregation (aggregate_init/3, aggregate_step/4, aggregate_final/3, ',
         'method_uses_visits/1, method_applies/2)' ].
code_culprit(undefined(PI, G)) -->
    !, [ '~q calls ~q, which this node does not define'-[G, PI] ].
code_culprit(unknown_call(G)) -->
    !, [ 'cannot tell which predicate ~q calls'-[G] ].
code_culprit(clause_head(H)) -->
    !, [ 'it may not define ~q'-[H] ].
code_culprit(hook(M:PI)) -->
    !, [ 'it may not define ~q, a hook called by name'-[M:PI] ].
code_culprit(directive(D)) -->
    !, [ 'directive ~q is not allowed'-[D] ].
code_culprit(handler(H)) -->
    !, [ 'its handler ~q is not defined by its own clauses'-[H] ].
code_culprit(data) -->
    !, [ 'it holds cyclic terms or attributed variables' ].
code_culprit(clause(E)) -->
    !, [ 'a clause cannot be defined (~p)'-[E] ].
code_culprit(M:F/A) -->
    { atom(M), atom(F), integer(A) },
    !, [ 'it calls ~q, which is not part of the agent API'-[M:F/A] ].
code_culprit(G) -->
    [ 'it calls ~q, which is not allowed in the sandbox'-[G] ].
